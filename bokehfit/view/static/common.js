// common.js: what both pages of the viewer share (viewer.js, the Cornell box; photo.js, a photo's
// compare): the element lookup, the writers of a served uniform layout's scalar types, and the
// adapter's name as the pages show it.

export const $ = (id) => document.getElementById(id);

// The DataView writer of each scalar type a served layout names (bokehfit.view.wgsl._PAGE_SCALARS):
// a field's components are written 4 bytes apart from its offset, little-endian.
export const SETTERS = { f32: "setFloat32", u32: "setUint32", i32: "setInt32" };

// The WebGPU adapter's vendor, architecture and description, as far as the browser tells them.
export function adapterName(adapter) {
  const info = adapter.info || {};
  return [info.vendor, info.architecture, info.description].filter(Boolean).join(" ") || "WebGPU";
}
