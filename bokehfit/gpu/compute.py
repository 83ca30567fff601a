"""Compute passes: bind buffers to a pipeline and dispatch it (the one place that does)."""

from __future__ import annotations

__all__ = ["bind_buffers", "dispatch"]


def bind_buffers(device, pipeline, *buffers):
    """Bind group 0 of ``pipeline`` with ``buffers`` at bindings 0, 1, 2, … in order."""
    return device.create_bind_group(
        layout=pipeline.get_bind_group_layout(0),
        entries=[{"binding": i, "resource": {"buffer": buffer}} for i, buffer in enumerate(buffers)],
    )


def dispatch(device, pipeline, bind_group, x: int, y: int = 1) -> None:
    """Submit one compute pass of ``x`` × ``y`` workgroups (not waited for)."""
    encoder = device.create_command_encoder()
    compute = encoder.begin_compute_pass()
    compute.set_pipeline(pipeline)
    compute.set_bind_group(0, bind_group)
    compute.dispatch_workgroups(x, y)
    compute.end()
    device.queue.submit([encoder.finish()])
