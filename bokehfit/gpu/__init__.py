"""The WebGPU side of bokehfit: adapter choice, shader loading, buffer layouts."""

from bokehfit.gpu.runtime import GPUContext, get_gpu

__all__ = ["GPUContext", "get_gpu"]
