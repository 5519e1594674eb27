"""The cooperative EKF backbone and the information bound (numba kernels and numpy references)."""
