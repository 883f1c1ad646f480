"""Pole-residue (modal) models: the form an identified modal model (LSCF poles + LSFD
residues) is exported to, evaluated as an FRF and simulated in time.

Model, for output ``o`` and input ``i``, at ``s = j omega``::

    H_oi(s) = sum_r [ R_r,oi / (s - lambda_r) + conj(R_r,oi) / (s - conj(lambda_r)) ]
              + LR_oi s^(p_o - 2) + UR_oi s^(p_o)

    lambda_r = -zeta_r omega_r + j omega_r sqrt(1 - zeta_r^2),   omega_r = 2 pi f_r

with ``p_o = 0`` for a displacement output (receptance, m/N), 1 for velocity (mobility,
(m/s)/N) and 2 for acceleration (accelerance, (m/s^2)/N): the residues ``R`` describe the
FRF in the output's own quantity per unit input force, and the lower (``LR``, mass-like in
receptance terms) and upper (``UR``, stiffness-like) residuals stand for the modes below and
above the band [1]_ [2]_. The file form is ``kind = "modal"`` in
:mod:`vibroscope.models.modelfile`.

References
----------
.. [1] W. Heylen, S. Lammens, P. Sas, *Modal Analysis Theory and Testing*, KU Leuven,
   1997, ch. A.2 (pole-residue form of the FRF, residual terms).
.. [2] D. J. Ewins, *Modal Testing: Theory, Practice and Application*, 2nd ed., Research
   Studies Press, 2000, sec. 4.4 (residual terms) and 2.7 (receptance, mobility, accelerance).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from vibroscope._checks import read_only as _ro

from vibroscope.models.lumped import Input, Output

__all__ = ["PoleResidueModel"]

#: the exponent p of s for each output quantity (H in the output's quantity = s^p x receptance)
QUANTITY_ORDER = {"displacement": 0, "velocity": 1, "acceleration": 2}
#: singular values below this fraction of the largest are dropped from a residue's rank
_RANK_TOL = 1e-13


def _complex_array(name: str, value, shape: tuple[int, ...]) -> np.ndarray:
    a = np.asarray(value)
    if a.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {a.shape}")
    a = a.astype(complex)
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be finite")
    return a


@dataclass(frozen=True, eq=False, kw_only=True)
class PoleResidueModel:
    """A modal model in pole-residue form with lower and upper residuals.

    ``H_oi(jw) = sum_r [R_r,oi / (jw - lambda_r) + conj(R_r,oi) / (jw - conj(lambda_r))]
    + LR_oi (jw)^(p-2) + UR_oi (jw)^p`` (see the module docstring for ``lambda_r`` and ``p``).

    Parameters
    ----------
    natural_frequencies : array_like, shape (n_modes,)
        Undamped natural frequencies ``f_r = omega_r / (2 pi)`` in Hz, > 0.
    damping_ratios : array_like, shape (n_modes,)
        Viscous damping ratios ``zeta_r``, ``0 <= zeta_r < 1`` (dimensionless).
    residues : array_like of complex, shape (n_modes, n_outputs, n_inputs)
        Residues ``R_r`` of the poles with positive imaginary part, in the output's quantity
        per N times rad/s (e.g. (m/s^2)/N * rad/s for an acceleration output).
    inputs : sequence of Input
        Force inputs (N), the columns of ``H``; ``dof`` is a free label.
    outputs : sequence of Output
        Outputs, the rows of ``H``; each ``quantity`` sets that row's ``p``.
    lower_residual : array_like of complex, shape (n_outputs, n_inputs), optional
        ``LR``, multiplying ``(jw)^(p-2)``; zeros if None.
    upper_residual : array_like of complex, shape (n_outputs, n_inputs), optional
        ``UR``, multiplying ``(jw)^p``; zeros if None.
    name : str
        Free label.

    Attributes
    ----------
    natural_frequencies, damping_ratios : ndarray, shape (n_modes,)
    residues : ndarray of complex, shape (n_modes, n_outputs, n_inputs)
    lower_residual, upper_residual : ndarray of complex, shape (n_outputs, n_inputs)
        Read-only arrays.

    Raises
    ------
    ValueError
        If there is no mode, a frequency is not > 0, a damping ratio is outside ``[0, 1)``,
        an array has the wrong shape or non-finite values, or channel names repeat.

    Notes
    -----
    Equality (``==``) compares every array exactly and the inputs, outputs and name.
    Time simulation (:func:`vibroscope.models.simulate.simulate`) uses the real state-space
    realisation :meth:`state_matrices`, which holds the pole-residue part exactly but only
    the proper, real-valued residual terms (see there).

    Examples
    --------
    One mode at 10 Hz, 2 % damping, receptance residue ``-j / (2 m omega_d)`` of 1 kg: the
    static receptance is ``1 / (m omega_r^2)``.

    >>> import numpy as np
    >>> from vibroscope.models.lumped import Input, Output
    >>> w = 2 * np.pi * 10.0
    >>> wd = w * np.sqrt(1 - 0.02**2)
    >>> m = PoleResidueModel.from_poles_residues(
    ...     [10.0], [0.02], [[[-0.5j / wd]]], inputs=["/f.x"],
    ...     outputs=[Output("y", "displacement", "/d.x")])
    >>> round(float(m.frf([0.0])[0, 0, 0].real * w**2), 12)
    1.0
    """

    natural_frequencies: np.ndarray
    damping_ratios: np.ndarray
    residues: np.ndarray
    inputs: tuple[Input, ...]
    outputs: tuple[Output, ...]
    lower_residual: np.ndarray | None = None
    upper_residual: np.ndarray | None = None
    name: str = ""

    def __post_init__(self) -> None:
        inputs = tuple(self.inputs)
        outputs = tuple(self.outputs)
        for i in inputs:
            if not isinstance(i, Input):
                raise TypeError(f"{i!r} is not an Input")
        for o in outputs:
            if not isinstance(o, Output):
                raise TypeError(f"{o!r} is not an Output")
        if not inputs or not outputs:
            raise ValueError(f"need at least one input and one output, got {len(inputs)=}, {len(outputs)=}")
        chans = [io.channel for io in inputs + outputs if io.channel is not None]
        if len(set(chans)) != len(chans):
            raise ValueError(f"channel names repeat: {chans}")
        f = np.atleast_1d(np.asarray(self.natural_frequencies, dtype=float))
        z = np.atleast_1d(np.asarray(self.damping_ratios, dtype=float))
        if f.ndim != 1 or f.size == 0:
            raise ValueError(f"natural_frequencies must be a non-empty 1-D array, got shape {f.shape}")
        if z.shape != f.shape:
            raise ValueError(f"damping_ratios must have shape {f.shape}, got {z.shape}")
        if not (np.all(np.isfinite(f)) and np.all(f > 0)):
            raise ValueError(f"natural_frequencies={f.tolist()} must be finite and > 0 Hz")
        if not (np.all(np.isfinite(z)) and np.all((z >= 0) & (z < 1))):
            raise ValueError(f"damping_ratios={z.tolist()} must satisfy 0 <= zeta < 1")
        shape = (len(outputs), len(inputs))
        R = _complex_array("residues", self.residues, (f.size,) + shape)
        lr = np.zeros(shape, complex) if self.lower_residual is None else self.lower_residual
        ur = np.zeros(shape, complex) if self.upper_residual is None else self.upper_residual
        lr = _complex_array("lower_residual", lr, shape)
        ur = _complex_array("upper_residual", ur, shape)
        for key, v in (("natural_frequencies", f), ("damping_ratios", z), ("residues", R),
                       ("lower_residual", lr), ("upper_residual", ur)):  # fmt: skip
            object.__setattr__(self, key, _ro(v))
        object.__setattr__(self, "inputs", inputs)
        object.__setattr__(self, "outputs", outputs)
        object.__setattr__(self, "name", str(self.name))

    def __eq__(self, other) -> bool:
        if not isinstance(other, PoleResidueModel):
            return NotImplemented
        arrays = ("natural_frequencies", "damping_ratios", "residues", "lower_residual", "upper_residual")
        return (
            self.inputs == other.inputs
            and self.outputs == other.outputs
            and self.name == other.name
            and all(np.array_equal(getattr(self, a), getattr(other, a)) for a in arrays)
        )

    __hash__ = None  # type: ignore[assignment]  # holds arrays

    # -- construction --------------------------------------------------------------------------
    @classmethod
    def from_poles_residues(
        cls,
        natural_frequencies,
        damping_ratios,
        residues,
        *,
        inputs: Sequence[Input | str],
        outputs: Sequence[Output | str],
        lower=None,
        upper=None,
        name: str = "",
    ) -> "PoleResidueModel":
        """A model from modal parameters and residues, e.g. an LSCF + LSFD identification.

        Parameters
        ----------
        natural_frequencies : array_like, shape (n_modes,)
            Undamped natural frequencies in Hz (``|lambda_r| / 2 pi``).
        damping_ratios : array_like, shape (n_modes,)
            Damping ratios (``-Re(lambda_r) / |lambda_r|``).
        residues : array_like of complex, shape (n_modes, n_outputs, n_inputs)
            Residues of the poles with positive imaginary part.
        inputs : sequence of Input or str
            The inputs; a string is a channel name (force input labelled ``"u"``).
        outputs : sequence of Output or str
            The outputs; a string is a channel name of an acceleration output labelled
            ``"y"``.
        lower, upper : array_like of complex, shape (n_outputs, n_inputs), optional
            Lower and upper residuals (zeros if None).
        name : str
            Free label.

        Returns
        -------
        PoleResidueModel

        Raises
        ------
        ValueError
            As :class:`PoleResidueModel`.
        """
        ins = tuple(i if isinstance(i, Input) else Input(dof="u", quantity="force", channel=str(i)) for i in inputs)
        outs = tuple(o if isinstance(o, Output) else Output("y", "acceleration", str(o)) for o in outputs)
        return cls(natural_frequencies=natural_frequencies, damping_ratios=damping_ratios, residues=residues,
                   inputs=ins,
                   outputs=outs, lower_residual=lower, upper_residual=upper, name=name)

    # -- the interface simulate() uses ---------------------------------------------------------
    @property
    def n_modes(self) -> int:
        """Number of modes (complex-conjugate pole pairs)."""
        return int(self.natural_frequencies.size)

    @property
    def elements(self) -> tuple:
        """No elements: a pole-residue model is linear (the simulator's dispatch reads this)."""
        return ()

    @property
    def is_linear(self) -> bool:
        """True unless an input saturates (the model itself is linear)."""
        return all(i.saturation is None for i in self.inputs)

    @property
    def eigenvalues(self) -> np.ndarray:
        """Poles ``lambda_r = -zeta_r omega_r + j omega_r sqrt(1 - zeta_r^2)`` (rad/s), shape (n_modes,)."""
        w = 2 * np.pi * self.natural_frequencies
        z = self.damping_ratios
        return _ro(-z * w + 1j * w * np.sqrt(1.0 - z**2))

    @property
    def output_orders(self) -> tuple[int, ...]:
        """``p`` of each output: 0 displacement, 1 velocity, 2 acceleration."""
        return tuple(QUANTITY_ORDER[o.quantity] for o in self.outputs)

    def input_channels(self) -> list[str]:
        """Channel names of the inputs (default ``/input{k}.x``)."""
        return [i.channel or f"/input{k}.x" for k, i in enumerate(self.inputs)]

    def output_channels(self) -> list[str]:
        """Channel names of the outputs (default ``/output{k}.x``)."""
        return [o.channel or f"/output{k}.x" for k, o in enumerate(self.outputs)]

    # -- analysis ------------------------------------------------------------------------------
    def frf(self, frequencies, *, realised: bool = False) -> np.ndarray:
        """The model's frequency response, outputs by inputs.

        Parameters
        ----------
        frequencies : array_like, shape (n_f,)
            Frequencies in Hz (>= 0).
        realised : bool
            False: the full pole-residue model with both residuals. True: the FRF of the
            time-domain realisation :meth:`state_matrices` (without the residual terms it
            drops), what :func:`~vibroscope.models.simulate.simulate` reproduces.

        Returns
        -------
        H : ndarray of complex, shape (n_f, n_outputs, n_inputs)
            In each output's quantity per N, times ``exp(-j w tau)`` for an input delay ``tau``.
            At 0 Hz a nonzero residual with a negative power of ``jw`` gives an infinite value.

        Raises
        ------
        ValueError
            If a frequency is negative or not finite.
        """
        f = np.atleast_1d(np.asarray(frequencies, dtype=float))
        if f.ndim != 1 or not np.all(np.isfinite(f)) or np.any(f < 0):
            raise ValueError("frequencies must be a 1-D array of finite frequencies >= 0")
        s = 2j * np.pi * f
        lam = self.eigenvalues
        R = self.residues
        p1 = 1.0 / (s[:, None] - lam[None, :])  # (n_f, n_modes)
        p2 = 1.0 / (s[:, None] - np.conj(lam)[None, :])
        H = np.einsum("fr,roi->foi", p1, R) + np.einsum("fr,roi->foi", p2, np.conj(R))
        LR, UR = self.lower_residual, self.upper_residual
        if realised:
            LR, UR = self._realised_residuals()
        for o, p in enumerate(self.output_orders):
            for res, e in ((LR[o], p - 2), (UR[o], p)):
                if np.any(res != 0):
                    se = np.empty_like(s)
                    nz = s != 0
                    se[nz] = s[nz] ** e
                    se[~nz] = np.inf if e < 0 else (1.0 if e == 0 else 0.0)
                    H[:, o, :] += se[:, None] * res[None, :]
        delays = np.array([i.delay for i in self.inputs])
        if np.any(delays):
            H *= np.exp(-s[:, None] * delays[None, :])[:, None, :]
        return H

    def _realised_residuals(self) -> tuple[np.ndarray, np.ndarray]:
        """The real parts of the residual terms with power 0 or -1 of ``jw``; zeros elsewhere."""
        LR = np.zeros(self.lower_residual.shape, complex)
        UR = np.zeros(self.upper_residual.shape, complex)
        for o, p in enumerate(self.output_orders):
            if p - 2 in (0, -1):
                LR[o] = self.lower_residual[o].real
            if p == 0:
                UR[o] = self.upper_residual[o].real
        return LR, UR

    def dropped_residual_terms(self) -> list[str]:
        """The nonzero residual terms that :meth:`state_matrices` cannot realise, in words."""
        out = []
        names = self.output_channels()
        for o, p in enumerate(self.output_orders):
            for label, res, e in (("lower", self.lower_residual[o], p - 2), ("upper", self.upper_residual[o], p)):
                term = f"{label} residual x (jw)^{e} of {names[o]!r}"
                if e in (0, -1):
                    if np.any(res.imag != 0):
                        out.append(f"imaginary part of the {term} (no real time-domain counterpart)")
                elif np.any(res != 0):
                    out.append(f"{term} ({'improper' if e > 0 else 'double integrator'})")
        return out

    def state_matrices(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """A real continuous-time state-space realisation ``(A, B, C, D)`` for simulation.

        Each mode ``r`` with residue ``R_r = U S V^H`` (SVD, rank ``k_r``: singular values
        above ``1e-13`` of the largest) becomes ``k_r`` complex states ``z' = lambda_r z +
        b u``, ``y = c z + conj(c z)``, ``c = U sqrt(S)``, ``b = sqrt(S) V^H``, each realised
        by the real pair ``x = [Re z, Im z]``::

            x' = [[sigma, -omega_d], [omega_d, sigma]] x + [Re b; Im b] u,
            y  = 2 [Re c, -Im c] x,        lambda_r = sigma + j omega_d,

        so ``C (sI - A)^-1 B`` equals the pole-residue sum exactly. Residual terms: the
        real part of a term in ``(jw)^0`` (``LR`` of an acceleration output, ``UR`` of a
        displacement output) goes to ``D``; the real part of ``LR (jw)^-1`` (velocity output)
        is realised as one integrator per input (its response to a force with a mean
        drifts, as the model says). Not realisable, hence dropped with a warning: the
        improper ``UR (jw)^1`` (velocity) and ``UR (jw)^2`` (acceleration), which would
        differentiate the input; ``LR (jw)^-2`` of a displacement output (a double
        integrator whose response to any force mean or initial transient grows without
        bound); and the imaginary part of any residual, which has no real-valued impulse
        response (it would break ``H(-jw) = conj H(jw)``). :meth:`frf` with
        ``realised=True`` is the transfer function of this realisation.

        Returns
        -------
        A : ndarray, shape (n_states, n_states)
        B : ndarray, shape (n_states, n_inputs)
        C : ndarray, shape (n_outputs, n_states)
        D : ndarray, shape (n_outputs, n_inputs)

        Warns
        -----
        RuntimeWarning
            If nonzero residual terms are dropped (listed in the message and by
            :meth:`dropped_residual_terms`).
        """
        n_o, n_i = len(self.outputs), len(self.inputs)
        blocks_A, blocks_B, blocks_C = [], [], []
        for lam, Rr in zip(self.eigenvalues, self.residues):
            U, S, Vh = np.linalg.svd(Rr, full_matrices=False)
            k = int(np.sum(S > _RANK_TOL * S[0])) if S.size and S[0] > 0 else 0
            sq = np.sqrt(S[:k])
            c = U[:, :k] * sq[None, :]  # (n_o, k)
            b = sq[:, None] * Vh[:k]  # (k, n_i)
            blk = np.array([[lam.real, -lam.imag], [lam.imag, lam.real]])
            for j in range(k):
                blocks_A.append(blk)
                blocks_B.append(np.vstack([b[j].real, b[j].imag]))
                blocks_C.append(2.0 * np.column_stack([c[:, j].real, -c[:, j].imag]))
        LR, UR = self._realised_residuals()
        D = np.zeros((n_o, n_i))
        C_int = np.zeros((n_o, n_i))
        for o, p in enumerate(self.output_orders):
            if p == 2:
                D[o] = LR[o].real
            elif p == 1:
                C_int[o] = LR[o].real
            else:
                D[o] = UR[o].real
        if np.any(C_int):
            blocks_A.append(np.zeros((n_i, n_i)))
            blocks_B.append(np.eye(n_i))
            blocks_C.append(C_int)
        n = sum(a.shape[0] for a in blocks_A)
        A = np.zeros((n, n))
        B = np.zeros((n, n_i))
        C = np.zeros((n_o, n))
        at = 0
        for a, bb, cc in zip(blocks_A, blocks_B, blocks_C):
            m = a.shape[0]
            A[at : at + m, at : at + m] = a
            B[at : at + m] = bb
            C[:, at : at + m] = cc
            at += m
        dropped = self.dropped_residual_terms()
        if dropped:
            warnings.warn(
                f"pole-residue model {self.name!r}: residual terms not realisable in the time "
                f"domain are left out of the simulation: {'; '.join(dropped)}",
                RuntimeWarning,
                stacklevel=2,
            )
        return A, B, C, D

