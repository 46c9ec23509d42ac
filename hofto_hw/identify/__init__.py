"""Offline dynamic identification (paper §III-A): regressor, base parameters, excitation
trajectories, least squares and physically consistent estimation, validation.

Modules: ``regressor`` (H_s of eq. (13)), ``base_params`` (eq. (14) regrouping), ``excitation``
(optimized Fourier series), ``estimate`` (OLS/WLS, eq. (15)), ``consistent`` (SDP),
``validation`` (RMSE figures); ``data`` reads and conditions recordings.
"""
