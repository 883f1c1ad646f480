"""Candidate effects of the gap diagnosis and the parameter vectors the fits move.

Each candidate is an :class:`EffectSpec`: an effect of :data:`~vibroscope.gap.report.EFFECTS`
at a location, with a small vector ``p`` of effect parameters (log-scaled where the
parameter is positive), its bounds and start values, and :meth:`EffectSpec.apply`, which
returns the lumped model augmented with the effect in today's model-file vocabulary:

=================  ==========================================================================
effect             model change
=================  ==========================================================================
time_delay         ``[[input]] delay`` (``delay_s``)
saturation         ``[[input]] saturation`` (``limit_N``)
coulomb_friction   a ``friction`` element at a connection (``Fc_N``; ``v_eps`` fixed)
backlash           the connection's spring replaced by a ``backlash`` element (``gap_m``)
hysteresis         a ``bouc_wen`` element at a connection (``alpha_N_per_m``, ``beta_per_m``,
                   ``gamma``, ``delta``; nu = 1)
cubic_stiffness    a ``cubic_spring`` (k = 0) at a connection (``k3_N_per_m3``)
extra_mode         an extra DOF joined to a DOF by spring + damper (``mass_kg``,
                   ``frequency_hz``, ``damping_ratio``)
=================  ==========================================================================

The linear parameters (masses, spring stiffnesses, damper coefficients) are moved by
:class:`LinearParams` as log factors on the nominal values.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np

from vibroscope.models.elements import (
    Backlash,
    BoucWen,
    CubicSpring,
    Damper,
    Friction,
    Spring,
)
from vibroscope.models.lumped import Dof, LumpedModel

__all__ = ["LinearParams", "EffectSpec", "connections", "candidate_specs", "FRICTION_V_EPS"]

#: regularisation velocity of fitted friction elements (m/s)
FRICTION_V_EPS = 1e-3
#: name of the DOF an extra_mode candidate adds
EXTRA_DOF = "extra"


def pair_name(between) -> str:
    """``"m2-m1"`` for ``between = ("m2", "m1")``."""
    return f"{between[0]}-{between[1]}"


def connections(model: LumpedModel) -> list[tuple[str, str]]:
    """The distinct element locations of `model` (as written), in model order.

    Parameters
    ----------
    model : LumpedModel
        The model whose elements are scanned.

    Returns
    -------
    list of tuple of (str, str)
        Each element's ``between`` once; ``(a, b)`` and ``(b, a)`` count as one location,
        kept as first written.
    """
    out: list[tuple[str, str]] = []
    for e in model.elements:
        if e.between not in out and (e.between[1], e.between[0]) not in out:
            out.append(e.between)
    return out


class LinearParams:
    """Log-factor parametrisation of a lumped model's linear parameters.

    Parameters are the DOF masses (``m:<dof>``), spring stiffnesses (``k:<a>-<b>``) and damper
    coefficients (``c:<a>-<b>``) of `model`; ``apply(model, theta)`` multiplies each by
    ``exp(theta_i)``. `which` restricts the set (``"all"``, ``"kc"`` (no masses),
    or an explicit list of names).

    Parameters
    ----------
    model : LumpedModel
        The nominal model; its DOFs, its :class:`~vibroscope.models.Spring` elements with
        ``k > 0`` and its :class:`~vibroscope.models.Damper` elements with ``c > 0`` give the
        parameters, in that order.
    which : {"all", "kc"} or iterable of str, optional
        ``"all"`` (default): every such parameter; ``"kc"``: stiffnesses and damping only;
        otherwise the names to keep (e.g. ``["k:m1-ground", "c:m1-ground"]``); unknown names
        are ignored.

    Attributes
    ----------
    names : list of str
        The parameter names, the order of ``theta``.
    refs : list of tuple of (str, int)
        For each name, its kind (``"m"``, ``"k"``, ``"c"``) and the index of its DOF or
        element in `model`.
    """

    def __init__(self, model: LumpedModel, which="all"):
        names, refs = [], []
        for i, d in enumerate(model.dofs):
            names.append(f"m:{d.name}")
            refs.append(("m", i))
        for j, e in enumerate(model.elements):
            if isinstance(e, Spring) and e.k > 0:
                names.append(f"k:{pair_name(e.between)}")
                refs.append(("k", j))
            elif isinstance(e, Damper) and e.c > 0:
                names.append(f"c:{pair_name(e.between)}")
                refs.append(("c", j))
        if which == "kc":
            keep = [i for i, n in enumerate(names) if not n.startswith("m:")]
        elif which == "all":
            keep = list(range(len(names)))
        else:
            keep = [i for i, n in enumerate(names) if n in set(which)]
        self.names = [names[i] for i in keep]
        self.refs = [refs[i] for i in keep]

    def __len__(self) -> int:
        return len(self.names)

    def apply(self, model: LumpedModel, theta) -> LumpedModel:
        """`model` with every parameter multiplied by ``exp(theta)``.

        Parameters
        ----------
        model : LumpedModel
            A model with the same DOFs and elements (by position) as the one this
            parametrisation was built from.
        theta : array_like, shape (len(self),)
            Log factors, one per name of :attr:`names`; empty returns `model` unchanged.

        Returns
        -------
        LumpedModel
        """
        theta = np.asarray(theta, float)
        if theta.size == 0:
            return model
        dofs = list(model.dofs)
        els = list(model.elements)
        for (kind, i), t in zip(self.refs, theta):
            f = math.exp(float(t))
            if kind == "m":
                dofs[i] = Dof(dofs[i].name, dofs[i].mass * f)
            elif kind == "k":
                els[i] = replace(els[i], k=els[i].k * f)
            else:
                els[i] = replace(els[i], c=els[i].c * f)
        return replace(model, dofs=tuple(dofs), elements=tuple(els))

    def changed(self, theta, tol: float = 0.03) -> list[str]:
        """Names of the parameters whose factor differs from 1 by more than `tol`.

        Parameters
        ----------
        theta : array_like, shape (len(self),)
            Log factors.
        tol : float, optional
            Relative change ``|exp(theta_i) - 1|`` above which a parameter counts as
            changed; default 0.03 (3 %).

        Returns
        -------
        list of str
        """
        return [n for n, t in zip(self.names, np.asarray(theta, float)) if abs(math.expm1(t)) > tol]

    def values(self, model: LumpedModel) -> dict[str, float]:
        """Current values (kg, N/m, N s/m) of the parameters in `model`.

        Parameters
        ----------
        model : LumpedModel
            A model with the same DOFs and elements (by position) as the nominal one.

        Returns
        -------
        dict of str to float
            Name -> mass (kg), stiffness (N/m) or damping coefficient (N s/m).
        """
        out = {}
        for n, (kind, i) in zip(self.names, self.refs):
            out[n] = model.dofs[i].mass if kind == "m" else (model.elements[i].k if kind == "k" else model.elements[i].c)
        return out


@dataclass
class EffectSpec:
    """One candidate effect at one location.

    Attributes
    ----------
    effect : str
    where : dict
    n : int
        Number of effect parameters ``p``.
    starts : list of ndarray
        Start vectors for the fit (a coarse grid).
    lower, upper : ndarray
        Bounds of ``p``.
    build : callable (model, p) -> LumpedModel
    describe : callable p -> dict
        The SI parameters of the report.
    linear : bool
        True when the augmented model is linear (fitted on the FRF, no time simulation).
    meta : dict
        Free-form extra information; default empty (vibroscope itself neither sets nor
        reads it).
    """

    effect: str
    where: dict
    n: int
    starts: list
    lower: np.ndarray
    upper: np.ndarray
    build: Callable
    describe: Callable
    linear: bool = False
    meta: dict = field(default_factory=dict)

    def apply(self, model: LumpedModel, p) -> LumpedModel:
        """`model` augmented with this effect: ``build(model, p)``.

        Parameters
        ----------
        model : LumpedModel
            The (linear-fitted) model to augment.
        p : array_like, shape (n,)
            The effect parameters, in the parametrisation of :attr:`lower` / :attr:`upper`.

        Returns
        -------
        LumpedModel
        """
        return self.build(model, np.asarray(p, float))

    @property
    def label(self) -> str:
        if "between" in self.where:
            return f"{self.effect}@{pair_name(self.where['between'])}"
        if "dof" in self.where:
            return f"{self.effect}@{self.where['dof']}"
        return self.effect


def _spring_at(model, between):
    for j, e in enumerate(model.elements):
        if isinstance(e, Spring) and set(e.between) == set(between):
            return j, e
    return None, None


def _k_at(model, between) -> float:
    j, e = _spring_at(model, between)
    if e is not None:
        return e.k
    return float(np.max(np.diag(model.K)))


def candidate_specs(model: LumpedModel, scales: dict) -> list[EffectSpec]:
    """Every candidate effect for `model` (except ``none`` and ``parameter_mismatch``).

    Parameters
    ----------
    model : LumpedModel
        The refitted nominal model.
    scales : dict
        Magnitudes from a simulation of `model` on the log: ``u_rms``, ``u_max`` (N),
        ``d_rms[pair]`` (m), ``v_rms[pair]`` (m/s) per connection, ``f_extra`` (list of
        start frequencies in Hz for extra modes), ``delay0`` (start delay, s).
    """
    specs: list[EffectSpec] = []
    u_max = scales["u_max"]

    # -- input side ---------------------------------------------------------------------------
    def build_delay(m, p):
        return replace(m, inputs=tuple(replace(i, delay=float(max(p[0], 0.0))) for i in m.inputs))

    d0 = scales.get("delay0", 0.002)
    specs.append(EffectSpec(
        "time_delay", {"side": "input"}, 1,
        [np.array([max(d0, 1e-4)]), np.array([0.002]), np.array([0.008])],
        np.array([0.0]), np.array([0.1]),
        build_delay, lambda p: {"delay_s": float(max(p[0], 0.0))}, linear=True,
    ))

    def build_sat(m, p):
        lim = float(math.exp(p[0]))
        return replace(m, inputs=tuple(replace(i, saturation=lim) for i in m.inputs))

    qs = scales.get("u_quantiles", [u_max * f for f in (0.9, 0.7, 0.5, 0.35)])
    specs.append(EffectSpec(
        "saturation", {"side": "input"}, 1,
        [np.array([math.log(q)]) for q in qs],
        np.array([math.log(0.02 * u_max)]), np.array([math.log(1.2 * u_max)]),
        build_sat, lambda p: {"limit_N": float(math.exp(p[0]))},
    ))

    # -- elements at connections ------------------------------------------------------------
    for pair in connections(model):
        key = pair_name(pair)
        d_rms = max(scales["d_rms"].get(key, 1e-6), 1e-12)
        k_loc = _k_at(model, pair)
        where = {"between": [pair[0], pair[1]]}

        # Coulomb friction: F = Fc tanh(v / v_eps)
        f_ref = k_loc * d_rms  # the spring force scale at this connection

        def build_fric(m, p, pair=pair):
            return replace(m, elements=m.elements + (Friction(pair, force_=float(math.exp(p[0])), v_eps=FRICTION_V_EPS),))

        specs.append(EffectSpec(
            "coulomb_friction", where, 1,
            [np.array([math.log(f_ref * r)]) for r in (0.01, 0.03, 0.1, 0.3, 1.0)],
            np.array([math.log(f_ref * 1e-4)]), np.array([math.log(max(f_ref, u_max) * 3)]),
            build_fric, lambda p: {"Fc_N": float(math.exp(p[0])), "v_eps_m_per_s": FRICTION_V_EPS},
        ))

        # backlash: the spring at the connection gets a clearance
        j, spring = _spring_at(model, pair)
        if spring is not None:
            def build_bl(m, p, pair=pair):
                jj, sp = _spring_at(m, pair)
                els = list(m.elements)
                els[jj] = Backlash(sp.between, k=sp.k, gap=float(math.exp(p[0])))
                return replace(m, elements=tuple(els))

            specs.append(EffectSpec(
                "backlash", where, 1,
                [np.array([math.log(d_rms * r)]) for r in (0.03, 0.1, 0.3, 1.0, 2.0)],
                np.array([math.log(d_rms * 1e-4)]), np.array([math.log(d_rms * 5)]),
                build_bl, lambda p: {"gap_m": float(math.exp(p[0]))},
            ))

        # cubic stiffness: k3 = q k / d_rms^2, q signed
        def build_cubic(m, p, pair=pair, k_loc=k_loc, d_rms=d_rms):
            return replace(m, elements=m.elements + (CubicSpring(pair, k3=float(p[0] * k_loc / d_rms**2), k=0.0),))

        specs.append(EffectSpec(
            "cubic_stiffness", where, 1,
            [np.array([q]) for q in (0.01, 0.03, 0.1, 0.3, 1.0, 3.0, 10.0, -0.01, -0.03, -0.1)],
            np.array([-0.5]), np.array([300.0]),
            build_cubic, lambda p, k_loc=k_loc, d_rms=d_rms: {"k3_N_per_m3": float(p[0] * k_loc / d_rms**2)},
        ))

        # Bouc-Wen hysteresis: z' = alpha v - beta (gamma |v| z + delta v |z|), nu = 1;
        # p = [log(alpha / k), log(beta d_rms), phi] with gamma = cos(phi), delta = sin(phi)
        def bw_coeffs(p, k_loc=k_loc, d_rms=d_rms):
            alpha = k_loc * math.exp(p[0])
            beta = math.exp(p[1]) / d_rms
            phi = float(np.clip(p[2], -1.45, 1.45))
            return alpha, beta, math.cos(phi), math.sin(phi)

        def build_bw(m, p, pair=pair, bw_coeffs=bw_coeffs):
            alpha, beta, gamma, delta = bw_coeffs(p)
            return replace(m, elements=m.elements + (BoucWen(pair, alpha=alpha, beta=beta, gamma=gamma, delta=delta, nu=1.0),))

        def desc_bw(p, bw_coeffs=bw_coeffs):
            alpha, beta, gamma, delta = bw_coeffs(p)
            return {"alpha_N_per_m": alpha, "beta_per_m": beta, "gamma": gamma, "delta": delta, "nu": 1.0}

        specs.append(EffectSpec(
            "hysteresis", where, 3,
            [np.array([math.log(a), math.log(b), s]) for a, b, s in ((0.3, 1.0, -0.9), (1.0, 3.0, -0.9), (0.3, 1.0, 0.6))],
            np.array([math.log(1e-3), math.log(1e-3), -1.45]), np.array([math.log(10.0), math.log(1e3), 1.45]),
            build_bw, desc_bw,
        ))

    # -- extra mode on each DOF -----------------------------------------------------------------
    for f0 in scales.get("f_extra", [])[:6]:
        for d in model.dofs:
            def build_em(m, p, dof=d.name):
                md = m.dofs[m.dof_index(dof)].mass
                me = md * math.exp(p[0])
                f = math.exp(p[1])
                zeta = math.exp(p[2])
                ke = me * (2 * math.pi * f) ** 2
                ce = 2 * zeta * math.sqrt(ke * me)
                return replace(
                    m,
                    dofs=m.dofs + (Dof(EXTRA_DOF, me),),
                    elements=m.elements + (Spring((EXTRA_DOF, dof), k=ke), Damper((EXTRA_DOF, dof), c=ce)),
                )

            def desc_em(p, dof=d.name, md=d.mass):
                return {"mass_kg": md * math.exp(p[0]), "frequency_hz": math.exp(p[1]), "damping_ratio": math.exp(p[2])}

            specs.append(EffectSpec(
                "extra_mode", {"dof": d.name, "frequency_hz": float(f0)}, 3,
                [np.array([math.log(r), math.log(f0), math.log(0.02)]) for r in (0.03, 0.1)],
                np.array([math.log(1e-3), math.log(f0 / 1.5), math.log(0.002)]),
                np.array([math.log(1.0), math.log(f0 * 1.5), math.log(0.2)]),
                build_em, desc_em, linear=True,
            ))
    return specs
