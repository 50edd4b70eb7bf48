"""Dryden turbulence (sim/plant/dryden.py): intensities, scales, seeding."""

import numpy as np
import pytest

from heliquad.sim.plant.dryden import LEVELS_KT, Dryden

DT = 0.005


@pytest.mark.parametrize("level", list(LEVELS_KT))
def test_gust_velocity_intensities_match_the_standard(level):
    # 20 minutes of gusts: the v channel's correlation time (L/V = 3.5 s at moderate) leaves
    # a sampling error of about 6 % (1 sigma) on its standard deviation; the bound is 15 %.
    d = Dryden(level, altitude_m=3.0, span_m=0.74, dt_s=DT, seed=11)
    x = np.array([d.step() for _ in range(int(1200 / DT))])
    std = x[:, :3].std(axis=0)
    np.testing.assert_allclose(std, [d.sigma_uv, d.sigma_uv, d.sigma_w], rtol=0.15)
    assert np.all(np.abs(x.mean(axis=0)[:3]) < 0.15 * std)


def test_intensity_scales_with_the_level_and_the_standards_low_altitude_form():
    light, severe = (Dryden(level, 3.0, 0.74, DT) for level in ("light", "severe"))
    assert severe.sigma_w == pytest.approx(3 * light.sigma_w)           # 45 kt vs 15 kt
    assert light.sigma_w == pytest.approx(0.1 * 15 * 0.514444)           # sigma_w = 0.1 W20
    # sigma_u / sigma_w = 1 / (0.177 + 0.000823 h)^0.4 at h = 10 ft (the floor)
    assert light.sigma_uv / light.sigma_w == pytest.approx(1 / (0.177 + 0.00823) ** 0.4)


def test_same_seed_same_turbulence():
    a, b = Dryden("moderate", 3.0, 0.74, DT, seed=4), Dryden("moderate", 3.0, 0.74, DT, seed=4)
    np.testing.assert_array_equal([a.step() for _ in range(100)], [b.step() for _ in range(100)])


def test_unknown_level_is_refused():
    with pytest.raises(ValueError, match="light, moderate"):
        Dryden("gale", 3.0, 0.74, DT)


def test_dryden_blocks_give_the_same_stream_as_single_steps():
    a, b = Dryden("severe", 3.0, 0.74, DT, seed=9), Dryden("severe", 3.0, 0.74, DT, seed=9)
    singles = np.array([a.step() for _ in range(300)])
    blocks = np.vstack([b.block(7), b.block(1), b.block(292)])
    np.testing.assert_allclose(blocks, singles, rtol=1e-12, atol=1e-15)


def test_imu_model_noise_bias_and_latency():
    # The sensor as the firmware sees it on the roll rig: the C++ plant adds the residual
    # bias and the drawn noise, and delays the sample by the DMP's latency.
    from heliquad.sim.plant.vehicle_params import load_params
    from heliquad.sim.plant.vehicle_plant import VehiclePlant

    p = load_params().imu
    plant = VehiclePlant("roll", "roll", DT, seed=3)
    gyro = []
    for k in range(20000):
        plant.vehicle.x[10] = 0.1 * k                      # the true roll rate this frame
        gyro.append(plant.sensor_sample()[1])
    gyro = np.array(gyro)
    sigma = plant.imu.gyro_sigma_rad_s
    # latency: the sample returned at step k is the one measured at k - latency
    assert gyro[5, 0] == pytest.approx(0.1 * (5 - p.dmp_latency_samples) + np.radians(p.gyro_bias_deg_s[0]),
                                       abs=5 * sigma)
    noise = gyro[:, 1] - np.radians(p.gyro_bias_deg_s[1])
    assert noise.std() == pytest.approx(np.radians(p.gyro_noise_deg_s_rt_hz) * np.sqrt(p.noise_bandwidth_hz), rel=0.05)
    assert noise.mean() == pytest.approx(0.0, abs=3 * sigma / np.sqrt(len(noise)))


def test_imu_noise_is_the_same_stream_in_blocks_and_frames():
    from heliquad.sim.plant.imu_model import ImuModel
    from heliquad.sim.plant.vehicle_params import load_params

    a, b = ImuModel(load_params().imu, seed=5), ImuModel(load_params().imu, seed=5)
    np.testing.assert_array_equal(np.vstack([a.noise(1) for _ in range(50)]),
                                  np.vstack([b.noise(20), b.noise(30)]))
