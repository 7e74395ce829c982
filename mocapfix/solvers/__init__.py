"""Shared numerical kernels: plain functions on arrays in a (T, C) layout (time along
axis 0, one column per channel), documented with the method they implement.

- :mod:`mocapfix.solvers.segments` — contiguous observed segments, gap interpolation,
  NaN-safe zero-phase filtering, Gaussian smoothing and wavelet denoising per segment.
- :mod:`mocapfix.solvers.localfit` — weighted (robust) local polynomial regression by
  convolution, vectorised over markers.
- :mod:`mocapfix.solvers.kalman` — constant-velocity Kalman filter + RTS smoother,
  vectorised over channels.
"""
