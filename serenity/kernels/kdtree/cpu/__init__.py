"""The kd-tree's CPU-only kernels: packets (``packets``) and the reordering passes (``sort``), whose
natives use clang's vector extensions, BMI2 and prefetches and are a ``__trap()`` on CUDA
(``..native``). The queries launch them on the CPU only (``..query``)."""
