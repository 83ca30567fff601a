"""The WebGPU side of bokehfit: adapter choice, shader loading, buffer layouts."""

from bokehfit.gpu.runtime import BACKENDS, AdapterChoice, GPUContext, get_gpu

__all__ = ["AdapterChoice", "BACKENDS", "GPUContext", "get_gpu"]
