"""WGSL sources of bokehfit, shipped as package data (loaded by bokehfit.gpu.shaders)."""
