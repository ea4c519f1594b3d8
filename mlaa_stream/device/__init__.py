"""The OpenCL context, device choice, program cache and colour tables."""
