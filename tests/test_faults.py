"""Signal faults (vibroscope.faults): each kind is found at the right place on a synthetic record
whose truth is known, a clean record yields none, and the documented action is applied."""

import json

import numpy as np
import pytest

from vibroscope.faults import FAULT_KINDS, Fault, apply_faults, detect_faults, nan_spans
from vibroscope.signals import Signals

FS = 100.0
N = 20_000


def _noise(seed=0, n=N):
    return np.random.default_rng(seed).standard_normal(n)


def _sig(*rows, units=None, names=None):
    names = names or [f"/c{k}" for k in range(len(rows))]
    return Signals(data=np.vstack(rows), fs=FS, channels=names, units=units or ["m/s^2"] * len(rows))


def _kinds(faults):
    return sorted((f.channel, f.kind) for f in faults)


def test_clean_records_have_no_fault_20_seeds():
    """Gaussian noise, a sine, a 12-bit quantised slow sine and quantised noise: no false alarm."""
    t = np.arange(N) / FS
    alarms = []
    for seed in range(20):
        rng = np.random.default_rng(seed)
        rows = [rng.standard_normal(N),
                np.sin(2 * np.pi * rng.uniform(5, 40) * t + rng.uniform(0, 6)),
                np.round(2047 * np.sin(2 * np.pi * rng.uniform(0.5, 2) * t)) / 2047 + 0 * t,
                np.round(30 * rng.standard_normal(N))]
        alarms += list(detect_faults(_sig(*rows), nperseg=1024))
    assert alarms == []


def test_nan_spans_counted_and_segments_skipped():
    x = _noise()
    x[1000:1010] = np.nan
    x[5000] = np.nan
    (f,) = detect_faults(_sig(x), nperseg=512)
    assert (f.kind, f.action, f.n_samples) == ("nan", "skip_segments", 11)
    assert f.spans == ((1000, 1010), (5000, 5001))
    assert f.times == ((10.0, 10.1), (50.0, 50.01))
    assert "11 missing samples" in f.message and "2 spans" in f.message
    assert nan_spans(x) == [(1000, 1010), (5000, 5001)]
    assert apply_faults(_sig(x), [f]).data is not None  # nothing to stop, nothing masked


def test_no_stretch_long_enough_or_all_nan_stops():
    x = _noise(n=4000)
    x[::300] = np.nan
    (f,) = detect_faults(_sig(x), nperseg=512)
    assert f.action == "stop" and "shorter nperseg" in f.message
    with pytest.raises(ValueError, match=r"nan in /c0: .*longest stretch without one is 299 samples"):
        apply_faults(_sig(x), [f])
    y = np.full(4000, np.nan)
    (g,) = detect_faults(_sig(y), nperseg=512)
    assert g.action == "stop" and "every sample is missing" in g.message


def test_inf_is_masked_as_missing():
    x = _noise()
    x[300] = np.inf
    x[301] = -np.inf
    x[9000] = np.inf
    (f,) = detect_faults(_sig(x), nperseg=512)
    assert (f.kind, f.action, f.spans) == ("inf", "mask", ((300, 302), (9000, 9001)))
    out = apply_faults(_sig(x), [f])
    assert np.isnan(out.data[0, [300, 301, 9000]]).all()
    assert np.array_equal(out.data[0, 302:9000], x[302:9000])  # nothing else touched


def test_clipping_at_both_rails_found_exactly():
    t = np.arange(N) / FS
    x = np.sin(2 * np.pi * 3.0 * t) + 0.01 * _noise(1)
    clipped = np.clip(x, -0.8, 0.75)
    truth = (x >= 0.75) | (x <= -0.8)
    faults = detect_faults(_sig(clipped), nperseg=1024)
    assert _kinds(faults) == [("/c0", "clipping")]
    (f,) = faults
    mask = np.zeros(N, bool)
    for a, b in f.spans:
        mask[a:b] = True
    assert np.array_equal(mask, truth)
    assert "0.75" in f.message and "-0.8" in f.message and f.action == "mask"
    out = apply_faults(_sig(clipped), faults)
    assert np.array_equal(np.isnan(out.data[0]), truth)


def test_dropout_zeros_and_held_value():
    x = _noise(2)
    x[3000:3100] = 0.0
    x[7000:7040] = x[6999]
    (f,) = detect_faults(_sig(x), nperseg=1024)
    assert (f.kind, f.action) == ("dropout", "mask")
    assert f.spans == ((3000, 3100), (6999, 7040))
    assert f.n_samples == 100 + 41
    y = _noise(3)
    y[100:150] = 0.0
    (g,) = detect_faults(_sig(y), nperseg=1024)
    assert "zeros" in g.message


def test_dc_offset_and_drift():
    x = _noise(4) + 5.0
    assert _kinds(detect_faults(_sig(x), nperseg=1024)) == [("/c0", "dc_offset")]
    ramp = _noise(5) + np.linspace(0, 20, N)
    kinds = _kinds(detect_faults(_sig(ramp), nperseg=1024))
    assert ("/c0", "drift") in kinds
    (d,) = [f for f in detect_faults(_sig(ramp), nperseg=1024) if f.kind == "drift"]
    assert d.action == "report" and "high-pass" in d.message


def test_missing_unit_constant_output_and_inputs():
    x = _noise(6)
    faults = detect_faults(_sig(x, np.full(N, 2.0), units=["", "m/s^2"]), nperseg=1024)
    assert _kinds(faults) == [("/c0", "missing_unit"), ("/c1", "constant")]
    drop = [f for f in faults if f.kind == "constant"][0]
    assert drop.action == "drop"
    assert apply_faults(_sig(x, np.full(N, 2.0)), faults).channels == ("/c0",)
    sig = _sig(np.zeros(N), x, names=["/force", "/acc"], units=["N", "m/s^2"])
    (z,) = detect_faults(sig, input="/force", nperseg=1024)
    assert (z.kind, z.action) == ("zero_input", "stop")
    with pytest.raises(ValueError, match=r"zero_input in /force: .*without --input"):
        apply_faults(sig, [z])
    sig = _sig(np.full(N, 3.0), x, names=["/force", "/acc"], units=["N", "m/s^2"])
    (c,) = detect_faults(sig, input="/force", nperseg=1024)
    assert (c.kind, c.action) == ("constant", "stop")


def test_short_record_stops():
    faults = detect_faults(_sig(_noise(n=500)), nperseg=1024)
    assert _kinds(faults) == [("/c0", "short_record")]
    with pytest.raises(ValueError, match=r"500 samples .* shorter than nperseg=1024.*shorter nperseg"):
        apply_faults(_sig(_noise(n=500)), faults)


def test_fault_is_reportable():
    x = _noise()
    x[10:20] = np.nan
    (f,) = detect_faults(_sig(x), nperseg=512)
    d = json.loads(json.dumps(f.to_dict()))
    assert d["kind"] == "nan" and d["spans"] == [[10, 20]] and d["times_s"] == [[0.1, 0.2]]
    assert str(f).startswith("nan in /c0: ")
    assert set(FAULT_KINDS) >= {"nan", "inf", "clipping", "dropout", "dc_offset", "drift", "missing_unit",
                                "constant", "zero_input", "short_record"}
    with pytest.raises(KeyError):
        detect_faults(_sig(x), input="/nope")
    assert isinstance(f, Fault)


def test_fault_lines_one_line_per_kind():
    """A kind found in many channels is one line naming them (the CLI prints one line per problem)."""
    from vibroscope.faults import fault_lines

    rng = np.random.default_rng(0)
    x = rng.standard_normal((5, 4000))
    x[:4, 1000:1010] = np.nan  # the same gap in four channels
    x[4] += 50.0  # a DC offset in one
    sig = Signals(data=x, fs=100.0, channels=[f"/c{k}" for k in range(5)], units=["m/s^2"] * 5)
    faults = detect_faults(sig, nperseg=256)
    lines = fault_lines(faults)
    assert [ln.split(" in ", 1)[0] for ln in lines] == ["nan", "dc_offset"]
    assert lines[0].startswith("nan in 4 channels (/c0, /c1, /c2 and 1 more); e.g. /c0: 10 missing samples")
    assert lines[1].startswith("dc_offset in /c4: ")
    assert sum(f.kind == "nan" for f in faults) == 4  # every fault kept in full


def test_a_value_beyond_any_measurement_is_masked_like_inf():
    """One sample of 1e300 (a corrupted value): an ``overflow`` fault naming the channel and the time,
    masked as missing (before: its square overflowed and the analysis stopped with "Eigenvalues did
    not converge" or LAPACK's "DLASCL parameter number 4 had an illegal value"); the other checks see
    it as missing (no drift of "inf times")."""
    from vibroscope.faults import OVERFLOW_LIMIT
    from vibroscope.pipeline import analyse_signals

    rng = np.random.default_rng(0)
    x = rng.standard_normal((2, 8000))
    x[0, 3000] = 1e300
    x[1, 5000] = -1e101
    sig = Signals(data=x, fs=1000.0, channels=["a", "b"], units=["m/s^2", "m/s^2"])
    faults = [f for f in detect_faults(sig, nperseg=512)]
    over = [f for f in faults if f.kind == "overflow"]
    assert [(f.channel, f.spans, f.action) for f in over] == [("a", ((3000, 3001),), "mask"), ("b", ((5000, 5001),),
                                                                                              "mask")]
    assert "3–3.001 s" in over[0].message and f"{OVERFLOW_LIMIT:.0e}" in over[0].message
    assert not [f for f in faults if f.kind == "drift"]
    masked = apply_faults(sig, faults)
    assert np.isnan(masked.data[0, 3000]) and np.isnan(masked.data[1, 5000])
    assert np.array_equal(np.isnan(masked.data).sum(axis=1), [1, 1])
    with np.errstate(over="raise", invalid="raise"):
        an = analyse_signals(sig, nperseg=512, method="fdd")
    assert np.isfinite(an.psd.values).all()
