"""Modal identification with the defaults on the close-mode 5-DOF chain, against its exact modes.

``vibroscope.models.close_modes_model()``: modes 12.0, 27.0, 45.0, 45.9, 80.0 Hz, ζ ≈ 1 %, the
pair at 45.0/45.9 Hz 2 % apart at modal overlap ≈ 1; 2 % output noise. Prints, per method, each
identified mode beside the true one (frequency error, relative damping error, MAC with the exact
complex shape) and any extra mode:

- LSCF + LSFD (``analyse_signals`` with the force, 512 s of white force at 256 Hz),
- SSI-COV (output-only, independent white forces on every mass, 2048 s),
- polyMAX on the output spectra (same ambient record),
- LSCF on the periodic multisine record (8192-sample period, 10 periods), period-synchronous,
  and, for comparison, on a Hann-window Welch H1 of the same record.

Run: ``python examples/modal/close_modes.py`` (about a minute).
"""

from __future__ import annotations

import numpy as np

from vibroscope.modal import auto_lscf, mac
from vibroscope.models import Input, close_modes_model
from vibroscope.models.simulate import simulate
from vibroscope.pipeline import analyse_signals
from vibroscope.spectral import frf

FS = 256.0


def report(name: str, mm, model) -> None:
    true = model.modes()
    dofs = [model.dof_index(o.dof) for o in model.outputs]
    print(f"{name}: {len(mm)} modes (true {len(true)})")
    used = set()
    for k in range(len(true)):
        j = int(np.argmin(np.abs(mm.natural_frequencies - true.natural_frequencies[k])))
        used.add(j)
        ef = 100 * (mm.natural_frequencies[j] / true.natural_frequencies[k] - 1)
        ez = 100 * (mm.damping_ratios[j] / true.damping_ratios[k] - 1)
        m = mac(mm.shapes[j], true.shapes[k, dofs])[0, 0]
        print(f"  {true.natural_frequencies[k]:7.3f} Hz -> {mm.natural_frequencies[j]:8.4f} Hz ({ef:+.4f} %), "
              f"zeta {100 * mm.damping_ratios[j]:.3f} % ({ez:+.2f} %), MAC {m:.5f}")
    extra = [f"{mm.natural_frequencies[j]:.3f}" for j in range(len(mm)) if j not in used]
    print("  spurious: " + (", ".join(extra) if extra else "none"))


def main() -> None:
    model = close_modes_model()
    u = np.random.default_rng(3).standard_normal(16 * 8192)
    forced = simulate(model, u, FS, noise=0.02, seed=4)
    report("LSCF + LSFD (force, 512 s)", analyse_signals(forced, input=model.input_channels()[0]).modal, model)

    amb_model = model.replace(inputs=tuple(Input(dof=d.name, channel=f"/f/{d.name}") for d in model.dofs))
    w = np.random.default_rng(1).standard_normal((model.n_dofs, 2048 * int(FS)))
    ambient = simulate(amb_model, w, FS, noise=0.02, seed=2).select(amb_model.output_channels())
    report("SSI-COV (ambient, 2048 s)", analyse_signals(ambient).modal, model)
    report("polyMAX on output spectra (ambient)", analyse_signals(ambient, method="polymax").modal, model)

    n, periods = 8192, 10
    rng = np.random.default_rng(7)
    k = np.arange(1, n // 2)
    lines = k[(k * FS / n > 5.0) & (k * FS / n < 100.0)]
    X = np.zeros(n // 2 + 1, complex)
    X[lines] = np.exp(2j * np.pi * rng.random(lines.size))
    one = np.fft.irfft(X, n)
    per = simulate(model, np.tile(one / one.std(), periods), FS, noise=0.02, seed=8)
    report("LSCF, periodic multisine (10 periods)", analyse_signals(per, input=model.input_channels()[0]).modal, model)
    # the same record through a Hann-window Welch H1 (what the periodic detection avoids)
    h = frf(per, model.input_channels()[0], nperseg=4096)
    report("LSCF on a Hann Welch H1 of the same periodic record (nperseg 4096)",
           auto_lscf(h, fmin=5.0, fmax=100.0).modes, model)


if __name__ == "__main__":
    main()
