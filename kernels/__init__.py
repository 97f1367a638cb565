"""CUDA C kernel sources (``*.cu``, ``*.cuh``), shared by the cuda and cpu backends; no Python code."""
