"""Astrobee simulator: the ISS, Astrobee and the cargo-bag models in pybullet, and sim_node.

One simulation is one process on one core: numpy's OpenBLAS worker threads only spin on the
other core beside a pybullet loop (measured ~4% of the FEM step in blas_thread_server, and the
core they take is the one the rest of the graph needs), so they are off unless the user says.
"""
import os as _os

_os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
