"""The headline speed cases of issue #9 as a pytest-benchmark suite (a few minutes).

``python -m pytest benchmarks/test_speed.py`` (not part of the test run: ``testpaths`` is ``tests``
and the package). Each benchmark group holds vibroscope and its baseline, timed in the same run, so
the factors in parentheses that pytest-benchmark prints beside each column are the ratios (the
baseline's over ours). Smaller sizes than ``benchmarks/all.py`` (whose table is in the README) so
that the suite runs in minutes; the ratios grow with the size, so they understate those of the
full runs:

- ``mcap-read``: a ROS 2 Imu log (1e5 messages, zstd) to an (N, 3) array: ``read_mcap`` against
  mcap-ros2-support's decoded messages and rerun 0.41's ``McapReader``.
- ``csd-vs-scipy``: the cross-spectral matrix of 10 channels × 5e5 samples (nperseg 4096, Hann,
  50 %): ``csd_matrix`` (float64 and float32 input) against 55 pairwise ``scipy.signal.csd``
  calls; ``csd-vs-np.sum``: the same (float64) against one ``np.sum`` read pass over the record
  (the factor of ``csd_matrix`` there is how many read passes it costs).
- ``startup``: ``vibroscope --help`` against ``python -c pass``.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pytest_benchmark")
sys.path.insert(0, str(Path(__file__).resolve().parent))

from mcap_ingest import _mcap_ros2, _rerun  # noqa: E402

N_MSGS = 100_000
N_CSD = 500_000
CHANNELS = [f"/imu.linear_acceleration.{c}" for c in "xyz"]


@pytest.fixture(scope="module")
def imu_log(tmp_path_factory):
    from vibroscope import Signals
    from vibroscope.io import write_ros2_mcap

    x = np.random.default_rng(1).standard_normal((3, N_MSGS))
    return write_ros2_mcap(tmp_path_factory.mktemp("bench") / "imu.mcap",
                           Signals(data=x, fs=1000.0, channels=CHANNELS, units=["m/s^2"] * 3, t0=1.7e9),
                           frame_id="imu_link")


@pytest.mark.benchmark(group="mcap-read")
def test_read_mcap(benchmark, imu_log):
    from vibroscope.io import read_mcap

    sig = benchmark.pedantic(read_mcap, args=(imu_log, CHANNELS), rounds=5, warmup_rounds=1)
    assert sig.data.shape == (3, N_MSGS)


@pytest.mark.benchmark(group="mcap-read")
def test_mcap_ros2_decoded_messages(benchmark, imu_log):
    a = benchmark.pedantic(_mcap_ros2, args=(imu_log, "/imu", N_MSGS), rounds=1)
    assert a.shape == (3, N_MSGS)


@pytest.mark.benchmark(group="mcap-read")
def test_rerun_mcap_reader(benchmark, imu_log):
    pytest.importorskip("rerun")
    a = benchmark.pedantic(_rerun, args=(imu_log, "/imu"), rounds=3)
    assert a.shape == (3, N_MSGS)


@pytest.fixture(scope="module")
def record():
    return np.random.default_rng(2).standard_normal((10, N_CSD))


def _csd(benchmark, x):
    from vibroscope.spectral import csd_matrix

    G = benchmark.pedantic(csd_matrix, args=(x, 1000.0), kwargs=dict(nperseg=4096), rounds=5, warmup_rounds=1)
    assert G.G.shape == (2049, 10, 10)


@pytest.mark.benchmark(group="csd-vs-scipy")
@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_csd_matrix(benchmark, record, dtype):
    _csd(benchmark, record.astype(dtype))


@pytest.mark.benchmark(group="csd-vs-np.sum")
def test_csd_matrix_against_one_read_pass(benchmark, record):
    _csd(benchmark, record)


@pytest.mark.benchmark(group="csd-vs-scipy")
def test_scipy_csd_pairwise(benchmark, record):
    import scipy.signal

    def pairs():
        return [scipy.signal.csd(record[i], record[j], 1000.0, nperseg=4096)[1]
                for i in range(10) for j in range(i, 10)]

    assert len(benchmark.pedantic(pairs, rounds=1)) == 55


@pytest.mark.benchmark(group="csd-vs-np.sum")
def test_np_sum_read_pass(benchmark, record):
    benchmark.pedantic(np.sum, args=(record,), rounds=20)


@pytest.mark.benchmark(group="startup")
def test_vibroscope_help(benchmark):
    benchmark.pedantic(subprocess.run, args=([sys.executable, "-m", "vibroscope.cli", "--help"],),
                       kwargs=dict(capture_output=True, check=True), rounds=5)


@pytest.mark.benchmark(group="startup")
def test_python_c_pass(benchmark):
    benchmark.pedantic(subprocess.run, args=([sys.executable, "-c", "pass"],), kwargs=dict(check=True), rounds=5)
