"""The interactive viewer: ``bokehfit view`` serves a page that path-traces the Cornell box in the browser.

The page (``static/``: index.html, style.css and the ES modules of viewer.js, one job
each: viewer_renderer.js, viewer_points.js, viewer_topdown.js, viewer_controls.js,
viewer_files.js, png_text.js, common.js) runs the package's own
WGSL path tracer through WebGPU, progressively, and draws a top-down sketch of
the box with the camera, the focus plane and the depth of field. The server
(:mod:`bokehfit.view.server`) hands it the shader with its includes resolved,
the uniform layout and every uniform value, all computed by the Python
renderer's code, so the browser and ``bokehfit render`` trace the same paths.

``bokehfit view PHOTO`` adds the photo's page (photo.html and the ES modules of photo.js:
photo_state.js, photo_draw.js, photo_edit.js, photo_results.js, photo_match.js,
photo_kernel.js, photo_refit.js, with common.js), whose compare runs in :mod:`bokehfit.view.photo`.
"""

from bokehfit.view.server import ViewerServer
from bokehfit.view.settings import COC_DIVISOR, DepthOfField, depth_of_field, settings_from_compare, viewer_config
from bokehfit.view.wgsl import pathtrace_source, uniform_layout, uniform_values

__all__ = [
    "COC_DIVISOR",
    "DepthOfField",
    "ViewerServer",
    "depth_of_field",
    "pathtrace_source",
    "settings_from_compare",
    "uniform_layout",
    "uniform_values",
    "viewer_config",
]
