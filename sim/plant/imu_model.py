"""The MPU6050 as the simulator presents it: noise, residual bias and DMP latency.

Applied between the true body state and the FIFO packets (the chip's quantisation is in the
packet encoder, sim/sensor/fifo_packets.cpp). Gyro and accelerometer white noise have the
datasheet's spectral densities over the DLPF's noise bandwidth; the gyro keeps a constant
residual bias; the DMP's attitude and rates come ``dmp_latency_samples`` loop samples late.

This class draws the noise (seeded, a block of frames at a time) and states the bias and
latency; the per-frame arithmetic (bias, noise, delay line) runs in C++ in the vehicle plant
(``heliquad._simcore.VehicleRig``), so a batch of frames needs no Python per frame.
"""

from __future__ import annotations

import math

import numpy as np

from heliquad import _simcore

from .vehicle_params import ImuParams

__all__ = ["ImuModel"]

UG_TO_M_S2 = _simcore.GRAVITY_M_S2 * 1e-6


class ImuModel:
    def __init__(self, params: ImuParams, seed: int = 0):
        self.p = params
        bw = math.sqrt(params.noise_bandwidth_hz)
        self.gyro_sigma_rad_s = math.radians(params.gyro_noise_deg_s_rt_hz) * bw
        self.accel_sigma_m_s2 = params.accel_noise_ug_rt_hz * UG_TO_M_S2 * bw
        self.bias_rad_s = np.radians(params.gyro_bias_deg_s)
        self._scale = np.array([self.gyro_sigma_rad_s] * 3 + [self.accel_sigma_m_s2] * 3)
        self.rng = np.random.default_rng(seed)

    def config(self):
        """Bias and latency for the C++ plant."""
        c = _simcore.ImuConfig()
        c.enabled, c.gyro_bias_rad_s = True, [float(b) for b in self.bias_rad_s]
        c.latency_samples = int(self.p.dmp_latency_samples)
        return c

    def noise(self, frames: int) -> np.ndarray:
        """``frames`` x 6 white-noise samples: gyro x y z (rad/s), accel x y z (m/s^2). The
        stream is the same whether drawn a frame or a block at a time."""
        return self.rng.standard_normal((frames, 6)) * self._scale
