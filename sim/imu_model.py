"""The MPU6050 as the simulator presents it: noise, residual bias and DMP latency.

Applied between the true body state and the FIFO packets (sim/mpu6050_packets.py, which
adds the chip's quantisation). Gyro and accelerometer white noise have the datasheet's
spectral densities over the DLPF's noise bandwidth; the gyro keeps a constant residual bias;
the DMP's attitude and rates come ``dmp_latency_samples`` loop samples late. Seeded.
"""

from __future__ import annotations

import collections
import math

import numpy as np

from .params import ImuParams

__all__ = ["ImuModel"]

UG_TO_M_S2 = 9.80665e-6


class ImuModel:
    def __init__(self, params: ImuParams, seed: int = 0):
        self.p = params
        bw = math.sqrt(params.noise_bandwidth_hz)
        self.gyro_sigma_rad_s = math.radians(params.gyro_noise_deg_s_rt_hz) * bw
        self.accel_sigma_m_s2 = params.accel_noise_ug_rt_hz * UG_TO_M_S2 * bw
        self.bias_rad_s = np.radians(params.gyro_bias_deg_s)
        self.rng = np.random.default_rng(seed)
        self.delay = collections.deque(maxlen=params.dmp_latency_samples + 1)

    def measure(self, q, rates, accel):
        """(quaternion, gyro rad/s, accel m/s^2) as the chip reports them this sample."""
        gyro = np.asarray(rates) + self.bias_rad_s + self.rng.normal(0.0, self.gyro_sigma_rad_s, 3)
        acc = np.asarray(accel) + self.rng.normal(0.0, self.accel_sigma_m_s2, 3)
        self.delay.append((list(q), list(gyro), list(acc)))
        return self.delay[0]             # the oldest held sample: latency samples ago
