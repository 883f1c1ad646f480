"""Elements that connect the DOFs of a lumped model: linear springs and dampers, and
nonlinear elements (cubic spring, backlash, friction, Bouc-Wen hysteresis, MR damper).

Every element joins two ends ``between = (a, b)``: two DOF names, or a DOF and
``"ground"``. With ``d = x_a - x_b`` and ``v = xdot_a - xdot_b`` the relative displacement
(m) and velocity (m/s), the element force ``f = force(d, v, state)`` (N) acts as ``-f`` on
`a` and ``+f`` on `b` (a positive stiffness pulls the ends together).

Elements with internal state have ``n_states > 0`` (Bouc-Wen 1, MR damper 2) and give the
derivative of their state with :meth:`state_derivative`.

Each element states the *linear part* it contributes to the model's ``K`` and ``C``
(``linear_stiffness``, ``linear_damping``); the lumped model's linear matrices hold those,
and the time integrator treats ``force - linear_stiffness*d - linear_damping*v`` as the
nonlinear remainder.

References
----------
.. [1] R. Bouc, "Forced vibrations of a mechanical system with hysteresis", Proc. 4th
   Conf. on Nonlinear Oscillations, Prague, 1967.
.. [2] Y.-K. Wen, "Method for random vibration of hysteretic systems", J. Eng. Mech. Div.
   ASCE 102(2):249-263, 1976.
.. [3] B. F. Spencer Jr., S. J. Dyke, M. K. Sain, J. D. Carlson, "Phenomenological model
   for magnetorheological dampers", J. Eng. Mech. 123(3):230-238, 1997.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
import math
from typing import ClassVar

import numpy as np

__all__ = [
    "GROUND",
    "Element",
    "Spring",
    "SignedDamper",
    "SignedMass",
    "SignedSpring",
    "Damper",
    "CubicSpring",
    "Backlash",
    "Friction",
    "BoucWen",
    "MRDamper",
    "spencer_mr_damper_rates",
    "ELEMENT_TYPES",
    "make_element",
]

#: name of the fixed reference end of an element
GROUND = "ground"


def _check_between(between) -> tuple[str, str]:
    b = tuple(str(x) for x in between)
    if len(b) != 2:
        raise ValueError(f"between must name two ends, got {between=}")
    if b[0] == b[1]:
        raise ValueError(f"an element cannot join {b[0]!r} to itself: {between=}")
    if b[0] == GROUND and b[1] == GROUND:
        raise ValueError(f"an element cannot join ground to ground: {between=}")
    return b


def _finite(name: str, value: float) -> float:
    value = float(value)
    if not np.isfinite(value):
        raise ValueError(f"{name}={value} must be finite")
    return value


def _nonneg(name: str, value: float) -> float:
    value = float(value)
    if not np.isfinite(value) or value < 0:
        raise ValueError(f"{name}={value} must be finite and >= 0")
    return value


@dataclass(frozen=True)
class Element:
    """Base class: an element between two ends (see module docstring).

    Parameters
    ----------
    between : tuple of (str, str)
        The two ends ``(a, b)``: two DOF names, or a DOF name and ``"ground"``.

    Raises
    ------
    ValueError
        If `between` does not name two ends, names the same end twice, or joins ground to
        ground.
    """

    between: tuple[str, str]

    #: element type name used in model files
    type: ClassVar[str] = "element"
    #: number of internal states
    n_states: ClassVar[int] = 0
    #: True when force is exactly linear_stiffness*d + linear_damping*v
    is_linear: ClassVar[bool] = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "between", _check_between(self.between))

    @property
    def linear_stiffness(self) -> float:
        """Stiffness (N/m) this element adds to the model's linear ``K``."""
        return 0.0

    @property
    def linear_damping(self) -> float:
        """Damping (N s/m) this element adds to the model's linear ``C``."""
        return 0.0

    @property
    def linear_mass(self) -> float:
        """Mass (kg) this element adds to the model's ``M`` across its ends (0 but for
        :class:`SignedMass`)."""
        return 0.0

    def force(self, d: float, v: float, state=None) -> float:
        """Element force in N for relative displacement `d` (m) and velocity `v` (m/s).

        Parameters
        ----------
        d : float
            Relative displacement ``x_a - x_b`` (m).
        v : float
            Relative velocity ``xdot_a - xdot_b`` (m/s).
        state : sequence of float, optional
            The element's internal states (length ``n_states``); None for elements without.

        Returns
        -------
        float
            The force ``f`` (N); it acts as ``-f`` on the first end and ``+f`` on the second.

        Raises
        ------
        NotImplementedError
            Always, on the base class: each element type implements it.
        """
        raise NotImplementedError

    def state_derivative(self, d: float, v: float, state) -> float:
        """Time derivative of the internal state (elements with ``n_states >= 1``).

        Parameters
        ----------
        d : float
            Relative displacement ``x_a - x_b`` (m).
        v : float
            Relative velocity ``xdot_a - xdot_b`` (m/s).
        state : sequence of float
            The element's internal states (length ``n_states``).

        Returns
        -------
        float
            The base class has no state and returns 0.0.
        """
        return 0.0

    def params(self) -> dict:
        """The element's parameters as a dict (model-file keys), without ``between``."""
        return {f.name: getattr(self, f.name) for f in fields(self) if f.name != "between"}


@dataclass(frozen=True)
class Spring(Element):
    """Linear spring ``f = k d``; `k` in N/m.

    Parameters
    ----------
    between : tuple of (str, str)
        The two ends: two DOF names, or a DOF name and ``"ground"``.
    k : float, optional
        Stiffness (N/m), finite and >= 0; default 0.

    Raises
    ------
    ValueError
        If `between` is invalid (see :class:`Element`) or `k` is negative or not finite.
    """

    k: float = 0.0
    type: ClassVar[str] = "spring"
    is_linear: ClassVar[bool] = True

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "k", _nonneg("k", self.k))

    @property
    def linear_stiffness(self) -> float:
        return self.k

    def force(self, d, v, state=None):
        """Element force (N) ``k d``.

        Parameters
        ----------
        d : float
            Relative displacement ``x_a - x_b`` (m).
        v : float
            Relative velocity ``xdot_a - xdot_b`` (m/s).
        state : sequence of float, optional
            Unused (no internal state).

        Returns
        -------
        float
            The force ``f`` (N); it acts as ``-f`` on the first end and ``+f`` on the second.
        """
        return self.k * d


@dataclass(frozen=True)
class SignedSpring(Element):
    """Linear spring of either sign ``f = k d``; `k` in N/m, may be negative.

    A stiffness taken out of (``k < 0``) or added to a connection whose stiffness is already
    in the model without a spring of its own to change: a modal-coordinates model, whose
    connections are spread over its modes. A clearance opened in such a connection is a
    ``SignedSpring(k=-k_c)`` beside a ``Backlash(k=k_c)`` (together ``-k_c clip(d, -gap, gap)``);
    a joint that slips in it, a ``SignedSpring(k=-k_j)`` beside the joint's Jenkins elements
    [1]_. Use :class:`Spring` for a physical spring: its stiffness must be positive.

    Parameters
    ----------
    between : tuple of (str, str)
        The two ends: two DOF or point names, or one and ``"ground"``.
    k : float, optional
        Stiffness (N/m), finite, any sign; default 0.

    Raises
    ------
    ValueError
        If `between` is invalid (see :class:`Element`) or `k` is not finite.

    References
    ----------
    .. [1] G. Kerschen, K. Worden, A. F. Vakakis, J.-C. Golinval, "Past, present and future of
       nonlinear system identification in structural dynamics", MSSP 20(3):505-592, 2006,
       sec. 5 (an underlying linear system plus localised nonlinear forces).
    """

    k: float = 0.0
    type: ClassVar[str] = "signed_spring"
    is_linear: ClassVar[bool] = True

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "k", _finite("k", self.k))

    # the same law as a spring's, k d: its linear part and its force
    linear_stiffness = Spring.linear_stiffness
    force = Spring.force


@dataclass(frozen=True)
class Damper(Element):
    """Linear viscous damper ``f = c v``; `c` in N s/m.

    Parameters
    ----------
    between : tuple of (str, str)
        The two ends: two DOF names, or a DOF name and ``"ground"``.
    c : float, optional
        Viscous damping coefficient (N s/m), finite and >= 0; default 0.

    Raises
    ------
    ValueError
        If `between` is invalid (see :class:`Element`) or `c` is negative or not finite.
    """

    c: float = 0.0
    type: ClassVar[str] = "damper"
    is_linear: ClassVar[bool] = True

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "c", _nonneg("c", self.c))

    @property
    def linear_damping(self) -> float:
        return self.c

    def force(self, d, v, state=None):
        """Element force (N) ``c v``.

        Parameters
        ----------
        d : float
            Relative displacement ``x_a - x_b`` (m).
        v : float
            Relative velocity ``xdot_a - xdot_b`` (m/s).
        state : sequence of float, optional
            Unused (no internal state).

        Returns
        -------
        float
            The force ``f`` (N); it acts as ``-f`` on the first end and ``+f`` on the second.
        """
        return self.c * v


@dataclass(frozen=True)
class SignedDamper(Element):
    """Linear viscous damper of either sign ``f = c v``; `c` in N s/m, may be negative.

    A damping change at a connection whose damping is already in the model without a damper
    of its own to change: a modal-coordinates model, whose damping is spread over its modes.
    Acting through the mode shapes it couples the modes (non-proportional damping), which
    per-mode damping factors cannot [1]_. Use :class:`Damper` for a physical damper: its
    coefficient must be positive. The model's total damping matrix must stay positive
    semi-definite for the model to be passive; this element does not check that.

    Parameters
    ----------
    between : tuple of (str, str)
        The two ends: two DOF or point names, or one and ``"ground"``.
    c : float, optional
        Viscous damping coefficient (N s/m), finite, any sign; default 0.

    Raises
    ------
    ValueError
        If `between` is invalid (see :class:`Element`) or `c` is not finite.

    References
    ----------
    .. [1] D. J. Ewins, *Modal Testing: Theory, Practice and Application*, 2nd ed., Research
       Studies Press, 2000, sec. 2.3 (non-proportional damping) and 6.2 (structural
       modification through the mode shapes).
    """

    c: float = 0.0
    type: ClassVar[str] = "signed_damper"
    is_linear: ClassVar[bool] = True

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "c", _finite("c", self.c))

    # the same law as a damper's, c v: its linear part and its force
    linear_damping = Damper.linear_damping
    force = Damper.force


@dataclass(frozen=True)
class SignedMass(Element):
    """A mass of either sign across its ends: ``m`` (kg) times ``l l^T`` in the mass matrix.

    To ground, a point mass added to (``m > 0``) or taken out of (``m < 0``) a measured point of a
    model whose masses are spread over its modes: a modal-coordinates model, where a physical
    mass that differs from the one the modes were identified with is ``Phi^T dM Phi`` in modal
    coordinates, coupling the modes [1]_; between two ends, an inerter (force ``m`` times the
    relative acceleration [2]_). It acts through the mass matrix only: its force is no function
    of the relative displacement and velocity, and :meth:`force` returns 0. The model's mass
    matrix must stay positive definite; this element does not check that.

    Parameters
    ----------
    between : tuple of (str, str)
        The two ends: two DOF or point names, or one and ``"ground"``.
    m : float, optional
        Mass (kg), finite, any sign; default 0.

    Raises
    ------
    ValueError
        If `between` is invalid (see :class:`Element`) or `m` is not finite.

    References
    ----------
    .. [1] D. J. Ewins, *Modal Testing: Theory, Practice and Application*, 2nd ed., Research
       Studies Press, 2000, sec. 6.2 (structural modification through the mode shapes).
    .. [2] M. C. Smith, "Synthesis of mechanical networks: the inerter", IEEE Trans. Automatic
       Control 47(10):1648-1662, 2002.
    """

    m: float = 0.0
    type: ClassVar[str] = "signed_mass"
    is_linear: ClassVar[bool] = True

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "m", _finite("m", self.m))

    @property
    def linear_mass(self) -> float:
        return self.m

    def force(self, d, v, state=None):
        """0: the element acts through the mass matrix (``linear_mass``), not as a force of
        `d` (m) and `v` (m/s).

        Parameters
        ----------
        d : float
            Relative displacement ``x_a - x_b`` (m), unused.
        v : float
            Relative velocity ``xdot_a - xdot_b`` (m/s), unused.
        state : sequence of float, optional
            Unused (no internal state).

        Returns
        -------
        float
            0.0 (N).
        """
        return 0.0


@dataclass(frozen=True)
class CubicSpring(Element):
    """Hardening or softening spring ``f = k d + k3 d^3 + k5 d^5`` (with ``k5`` unset: hardening
    for ``k3 > 0``, softening for ``k3 < 0``).

    `k` in N/m (its linear part, may be 0), `k3` in N/m^3, `k5` in N/m^5 (optional: the odd
    polynomial restoring force of a Duffing oscillator carried one order further, as in the
    polynomial stiffness of nonlinear normal-mode and harmonic-balance work; Kerschen, Worden,
    Vakakis & Golinval, "Past, present and future of nonlinear system identification in
    structural dynamics", Mech. Syst. Signal Process. 20, 2006).

    Parameters
    ----------
    between : tuple of (str, str)
        The two ends: two DOF names, or a DOF name and ``"ground"``.
    k3 : float, optional
        Cubic stiffness (N/m^3), finite, either sign; default 0.
    k : float, optional
        Linear stiffness (N/m), finite and >= 0; default 0. It is the part the element adds
        to the model's linear ``K``.
    k5 : float or None, optional
        Quintic stiffness (N/m^5), finite, either sign; default None (no quintic term, and
        none written to the model file).

    Raises
    ------
    ValueError
        If `between` is invalid (see :class:`Element`), `k` is negative or not finite, or
        `k3` or `k5` is not finite.
    """

    k3: float = 0.0
    k: float = 0.0
    k5: float | None = None
    type: ClassVar[str] = "cubic_spring"

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "k", _nonneg("k", self.k))
        object.__setattr__(self, "k3", _finite("k3", self.k3))
        if self.k5 is not None:
            object.__setattr__(self, "k5", _finite("k5", self.k5))

    @property
    def linear_stiffness(self) -> float:
        return self.k

    def force(self, d, v, state=None):
        """Element force (N) ``k d + k3 d^3 + k5 d^5``.

        Parameters
        ----------
        d : float
            Relative displacement ``x_a - x_b`` (m).
        v : float
            Relative velocity ``xdot_a - xdot_b`` (m/s).
        state : sequence of float, optional
            Unused (no internal state).

        Returns
        -------
        float
            The force ``f`` (N); it acts as ``-f`` on the first end and ``+f`` on the second.
        """
        k5 = self.k5 or 0.0
        return self.k * d + self.k3 * d * d * d + k5 * d**5


@dataclass(frozen=True)
class Backlash(Element):
    """Spring with a clearance (dead zone): ``f = k (d - gap sign d)`` for ``|d| > gap``, else 0.

    `k` in N/m, `gap` in m (half the total free play).

    Parameters
    ----------
    between : tuple of (str, str)
        The two ends: two DOF names, or a DOF name and ``"ground"``.
    k : float, optional
        Contact stiffness outside the clearance (N/m), finite and >= 0; default 0.
    gap : float, optional
        Half the total free play (m), finite and >= 0; default 0.

    Raises
    ------
    ValueError
        If `between` is invalid (see :class:`Element`) or `k` or `gap` is negative or not
        finite.
    """

    k: float = 0.0
    gap: float = 0.0
    type: ClassVar[str] = "backlash"

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "k", _nonneg("k", self.k))
        object.__setattr__(self, "gap", _nonneg("gap", self.gap))

    def force(self, d, v, state=None):
        """Element force (N) ``k (d - gap sign d)`` outside the clearance, 0 inside.

        Parameters
        ----------
        d : float
            Relative displacement ``x_a - x_b`` (m).
        v : float
            Relative velocity ``xdot_a - xdot_b`` (m/s).
        state : sequence of float, optional
            Unused (no internal state).

        Returns
        -------
        float
            The force ``f`` (N); it acts as ``-f`` on the first end and ``+f`` on the second.
        """
        if d > self.gap:
            return self.k * (d - self.gap)
        if d < -self.gap:
            return self.k * (d + self.gap)
        return 0.0


@dataclass(frozen=True)
class Friction(Element):
    """Regularised Coulomb friction, symmetric ``f = force tanh(v / v_eps)`` or asymmetric.

    `force` is the sliding friction force in N for positive relative velocity, `force_neg`
    (N) the one for negative relative velocity (None: the same, symmetric), `v_eps` (m/s)
    the regularisation velocity (default 1e-3 m/s). With ``t = tanh(v / v_eps)``::

        f = force t        (v >= 0)
        f = force_neg t    (v < 0)

    continuous (``t = 0`` at ``v = 0``) and monotonic in `v` for any pair of forces, with
    ``f -> +force`` for ``v >> v_eps`` and ``f -> -force_neg`` for ``v << -v_eps``; for
    ``force_neg = force`` (or None) it is ``force t`` exactly.

    Parameters
    ----------
    between : tuple of (str, str)
        The two ends: two DOF names, or a DOF name and ``"ground"``.
    force_ : float, optional
        Sliding (Coulomb) friction force (N) for positive relative velocity, finite and
        >= 0; default 0. Stored under the trailing-underscore name because :meth:`force` is
        the method; the model-file key (and :meth:`params`) call it ``force``.
    v_eps : float, optional
        Regularisation velocity (m/s), > 0; default 1e-3.
    force_neg : float or None, optional
        Sliding friction force (N) for negative relative velocity, finite and >= 0; default
        None (symmetric: ``force_``). Model-file key ``force_neg``, omitted when None.

    Raises
    ------
    ValueError
        If `between` is invalid (see :class:`Element`), `force_` or `force_neg` is negative
        or not finite, or `v_eps` is not > 0.
    """

    force_: float = 0.0
    v_eps: float = 1e-3
    force_neg: float | None = None
    type: ClassVar[str] = "friction"

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "force_", _nonneg("force", self.force_))
        v_eps = float(self.v_eps)
        if not np.isfinite(v_eps) or v_eps <= 0:
            raise ValueError(f"{v_eps=} must be > 0")
        object.__setattr__(self, "v_eps", v_eps)
        if self.force_neg is not None:
            object.__setattr__(self, "force_neg", _nonneg("force_neg", self.force_neg))

    @property
    def force_negative(self) -> float:
        """Sliding force (N) for negative relative velocity: `force_neg`, or `force_` if None."""
        return self.force_ if self.force_neg is None else self.force_neg

    def force(self, d, v, state=None):
        """Element force (N) ``force_ t`` for ``v >= 0`` and ``force_neg t`` for ``v < 0``,
        ``t = tanh(v / v_eps)``; it does not depend on `d` (symmetric, ``force_neg`` None:
        ``force_ t``).

        Parameters
        ----------
        d : float
            Relative displacement ``x_a - x_b`` (m).
        v : float
            Relative velocity ``xdot_a - xdot_b`` (m/s).
        state : sequence of float, optional
            Unused (no internal state).

        Returns
        -------
        float
            The force ``f`` (N); it acts as ``-f`` on the first end and ``+f`` on the second.
        """
        t = math.tanh(v / self.v_eps)
        if self.force_neg is None:
            return self.force_ * t
        return (self.force_ if v >= 0 else self.force_neg) * t

    def params(self) -> dict:
        """The parameters under their model-file keys: ``force``, ``v_eps`` and, when not
        None, ``force_neg`` (N)."""
        p = {"force": self.force_, "v_eps": self.v_eps}
        if self.force_neg is not None:
            p["force_neg"] = self.force_neg
        return p


@dataclass(frozen=True, kw_only=True)
class BoucWen(Element):
    """Bouc-Wen hysteretic element: force ``z`` with
    ``zdot = alpha v - beta (gamma |v| |z|^(nu-1) z + delta v |z|^nu)``.

    Parameters are those of Noël & Schoukens (2016): `alpha` in N/m, `beta` in 1/m
    (for ``nu = 1``), `gamma`, `delta` and `nu` dimensionless. Defaults are the benchmark's.

    Parameters
    ----------
    between : tuple of (str, str)
        The two ends: two DOF names, or a DOF name and ``"ground"``.
    alpha : float, optional
        Stiffness gain of the hysteretic force (N/m); default 5.0e4.
    beta : float, optional
        Hysteresis amplitude (1/m for ``nu = 1``); default 1.0e3.
    gamma : float, optional
        Hysteresis shape, dimensionless; default 0.8.
    delta : float, optional
        Hysteresis shape, dimensionless; default -1.1.
    nu : float, optional
        Hysteresis exponent, dimensionless, > 0; default 1.0.

    Raises
    ------
    ValueError
        If `between` is invalid (see :class:`Element`), a parameter is not finite, or
        ``nu <= 0``.
    """

    alpha: float = 5.0e4
    beta: float = 1.0e3
    gamma: float = 0.8
    delta: float = -1.1
    nu: float = 1.0
    type: ClassVar[str] = "bouc_wen"
    n_states: ClassVar[int] = 1

    def __post_init__(self) -> None:
        super().__post_init__()
        for name in ("alpha", "beta", "gamma", "delta", "nu"):
            val = float(getattr(self, name))
            if not np.isfinite(val):
                raise ValueError(f"{name}={val} must be finite")
            object.__setattr__(self, name, val)
        if self.nu <= 0:
            raise ValueError(f"nu={self.nu} must be > 0")

    def force(self, d, v, state=None):
        """Element force (N) ``z``, the hysteretic state itself; `d` and `v` are unused.

        Parameters
        ----------
        d : float
            Relative displacement ``x_a - x_b`` (m).
        v : float
            Relative velocity ``xdot_a - xdot_b`` (m/s).
        state : sequence of float, optional
            ``(z,)``, the hysteretic force (N); None gives 0.0.

        Returns
        -------
        float
            The force ``f`` (N); it acts as ``-f`` on the first end and ``+f`` on the second.
        """
        return state[0] if state is not None else 0.0

    def state_derivative(self, d, v, state):
        """Rate ``zdot`` (N/s) of the hysteretic force (see the class docstring).

        Parameters
        ----------
        d : float
            Relative displacement (m); unused (the law depends on the velocity only).
        v : float
            Relative velocity ``xdot_a - xdot_b`` (m/s).
        state : float or sequence of float
            ``z`` (N), or ``(z,)``.

        Returns
        -------
        float
            ``alpha v - beta (gamma |v| |z|^(nu-1) z + delta v |z|^nu)``, N/s.
        """
        z = state[0] if not isinstance(state, float) else state
        az = abs(z)
        if self.nu == 1.0:
            return self.alpha * v - self.beta * (self.gamma * abs(v) * z + self.delta * v * az)
        return self.alpha * v - self.beta * (
            self.gamma * abs(v) * az ** (self.nu - 1.0) * z + self.delta * v * az**self.nu
        )


def spencer_mr_damper_rates(x, xdot, y, z, *, alpha, c0, c1, k0, gamma, beta, A, n):
    """Spencer et al. (1997) MR-damper law, eq. 5: the rates ``(ydot, zdot)`` of the internal states.

    The one implementation of the law, used by :class:`MRDamper` and by the MR-damper
    instrument (:mod:`vibroscope.instruments.mr_damper`)::

        ydot = (alpha z + c0 xdot + k0 (x - y)) / (c0 + c1)
        zdot = -gamma |xdot - ydot| z |z|^(n-1) - beta (xdot - ydot) |z|^n + A (xdot - ydot)

    The damper force is then ``f = c1 ydot + k1 (x - x0)``.

    Parameters
    ----------
    x, xdot : float or ndarray
        Damper displacement (m) and velocity (m/s).
    y, z : float or ndarray
        Internal displacement y (m) and hysteretic variable z (m).
    alpha, c0, c1, k0 : float
        Coefficients at the present current: Bouc-Wen force gain (N/m), viscous damping at
        large and at low velocities (N s/m), stiffness at large velocities (N/m).
    gamma, beta : float
        Hysteresis shape parameters, m^-n.
    A : float
        Hysteresis scale, dimensionless.
    n : float
        Hysteresis exponent, dimensionless.

    Returns
    -------
    tuple (ydot, zdot)
        In m/s; scalars for scalar arguments, arrays for arrays (``abs`` is the builtin, so
        python floats stay fast in a scalar integration loop).
    """
    ydot = (alpha * z + c0 * xdot + k0 * (x - y)) / (c0 + c1)
    r = xdot - ydot
    az = abs(z)
    zdot = -gamma * abs(r) * z * az ** (n - 1) - beta * r * az**n + A * r
    return ydot, zdot


@dataclass(frozen=True, kw_only=True)
class MRDamper(Element):
    """Magnetorheological damper, the phenomenological model of Spencer et al. (1997), eq. 5.

    Internal states: the Bouc-Wen variable ``z`` and the internal displacement ``y``
    (2 states). With ``x = d`` and ``xdot = v``::

        zdot = -gamma |xdot - ydot| z |z|^(n-1) - beta (xdot - ydot) |z|^n + A (xdot - ydot)
        ydot = (alpha z + c0 xdot + k0 (x - y)) / (c0 + c1)
        f    = c1 ydot + k1 (x - x0)

    The current-dependent coefficients follow the paper's linear laws in the coil current
    `current` (A): ``alpha = alpha_a + alpha_b i``, ``c0 = c0_a + c0_b i``,
    ``c1 = c1_a + c1_b i``. Defaults are the values identified in Spencer et al. (1997),
    Table 1, converted to SI (N/cm -> 1e2 N/m, N s/cm -> 1e2 N s/m, cm^-2 -> 1e4 m^-2);
    the paper's laws are per volt of the current driver's command (with a first-order
    filter ``udot = -eta (u - v)``, eta = 190 1/s, left out here: the current is taken as
    constant), taken here per ampere.

    Notes
    -----
    The law itself is :func:`spencer_mr_damper_rates`, shared with the MR-damper instrument;
    :meth:`from_coefficients` builds the element from
    :meth:`vibroscope.instruments.mr_damper.MRDamperParams.at_current` (its cubic current
    laws and A/V mapping). The offset force ``-k1 x0`` is omitted (a static preload). State
    order: ``(z, y)``.

    Parameters
    ----------
    between : tuple of (str, str)
        The two ends: two DOF names, or a DOF name and ``"ground"``.
    current : float, optional
        Coil current ``i`` (A), taken as constant; default 0. (Model-file key ``i``.)
    alpha_a, alpha_b : float, optional
        ``alpha = alpha_a + alpha_b i``: Bouc-Wen force gain (N/m) and its slope (N/(m A));
        defaults 140.0e2 and 695.0e2.
    c0_a, c0_b : float, optional
        ``c0 = c0_a + c0_b i``: viscous damping at large velocities (N s/m) and its slope
        (N s/(m A)); defaults 21.0e2 and 3.50e2.
    c1_a, c1_b : float, optional
        ``c1 = c1_a + c1_b i``: viscous damping at low velocities (N s/m) and its slope
        (N s/(m A)); defaults 283.0e2 and 2.95e2.
    k0 : float, optional
        Stiffness at large velocities (N/m); default 46.9e2.
    k1 : float, optional
        Accumulator stiffness (N/m), the element's linear stiffness; default 5.0e2.
    gamma, beta : float, optional
        Hysteresis shape parameters (m^-n); defaults 363.0e4 each.
    A : float, optional
        Hysteresis scale, dimensionless; default 301.0.
    n : float, optional
        Hysteresis exponent, dimensionless; default 2.0.

    Raises
    ------
    ValueError
        If `between` is invalid (see :class:`Element`). The coefficients are not checked.
    """

    current: float = 0.0
    alpha_a: float = 140.0e2
    alpha_b: float = 695.0e2
    c0_a: float = 21.0e2
    c0_b: float = 3.50e2
    c1_a: float = 283.0e2
    c1_b: float = 2.95e2
    k0: float = 46.9e2
    k1: float = 5.0e2
    gamma: float = 363.0e4
    beta: float = 363.0e4
    A: float = 301.0
    n: float = 2.0
    type: ClassVar[str] = "mr_damper"
    n_states: ClassVar[int] = 2

    @classmethod
    def from_coefficients(cls, between, coeffs) -> "MRDamper":
        """An element with fixed coefficients taken from any object with attributes
        ``alpha, c0, c1, k0, k1, gamma, beta, A, n`` (e.g.
        :meth:`vibroscope.instruments.mr_damper.MRDamperParams.at_current`); ``x0`` is dropped.

        Parameters
        ----------
        between : tuple of (str, str)
            The two ends: two DOF names, or a DOF name and ``"ground"``.
        coeffs : object
            Has attributes ``alpha`` (N/m), ``c0``, ``c1`` (N s/m), ``k0``, ``k1`` (N/m),
            ``gamma``, ``beta`` (m^-n), ``A`` and ``n`` (dimensionless), in SI units; they
            become the current-independent parts (``*_a``), with ``current = 0`` and the
            ``*_b`` slopes 0.

        Returns
        -------
        MRDamper
        """
        return cls(
            between,
            current=0.0,
            alpha_a=coeffs.alpha,
            alpha_b=0.0,
            c0_a=coeffs.c0,
            c0_b=0.0,
            c1_a=coeffs.c1,
            c1_b=0.0,
            k0=coeffs.k0,
            k1=coeffs.k1,
            gamma=coeffs.gamma,
            beta=coeffs.beta,
            A=coeffs.A,
            n=coeffs.n,
        )

    def coefficients(self) -> tuple[float, float, float]:
        """``(alpha, c0, c1)`` at the element's current: each ``a + b * current``.

        Returns
        -------
        tuple of float
            ``alpha`` (N/m), ``c0`` and ``c1`` (N s/m), the current-dependent parameters of Spencer et
            al. (1997).
        """
        i = self.current
        return self.alpha_a + self.alpha_b * i, self.c0_a + self.c0_b * i, self.c1_a + self.c1_b * i

    def _rates(self, d, v, state):
        alpha, c0, c1 = self.coefficients()
        return spencer_mr_damper_rates(d, v, state[1], state[0], alpha=alpha, c0=c0, c1=c1, k0=self.k0,
                                       gamma=self.gamma, beta=self.beta, A=self.A, n=self.n)

    @property
    def linear_stiffness(self) -> float:
        return self.k1

    def force(self, d, v, state=None):
        """Element force (N) ``c1 ydot + k1 d``; without `state`, only the spring part ``k1 d``.

        Parameters
        ----------
        d : float
            Relative displacement ``x_a - x_b`` (m).
        v : float
            Relative velocity ``xdot_a - xdot_b`` (m/s).
        state : sequence of float, optional
            ``(z, y)``: the hysteretic variable z (m) and internal displacement y (m);
            None gives ``k1 d``.

        Returns
        -------
        float
            The force ``f`` (N); it acts as ``-f`` on the first end and ``+f`` on the second.
        """
        if state is None:
            return self.k1 * d
        _, _, c1 = self.coefficients()
        ydot, _ = self._rates(d, v, state)
        return c1 * ydot + self.k1 * d

    def state_derivative(self, d, v, state):
        """Rates of the internal states, by :func:`spencer_mr_damper_rates`.

        Parameters
        ----------
        d : float
            Relative displacement ``x_a - x_b`` (m), the law's ``x``.
        v : float
            Relative velocity ``xdot_a - xdot_b`` (m/s), the law's ``xdot``.
        state : sequence of float
            ``(z, y)``: the hysteretic variable z (m) and the internal displacement y (m).

        Returns
        -------
        ndarray, shape (2,)
            ``(zdot, ydot)``, m/s, in the state order.
        """
        ydot, zdot = self._rates(d, v, state)
        return np.array([zdot, ydot])


#: model-file type name -> (class, {file key: attribute}, required keys)
ELEMENT_TYPES: dict[str, tuple[type, dict[str, str], tuple[str, ...]]] = {
    "spring": (Spring, {"k": "k"}, ("k",)),
    "signed_spring": (SignedSpring, {"k": "k"}, ("k",)),
    "damper": (Damper, {"c": "c"}, ("c",)),
    "signed_damper": (SignedDamper, {"c": "c"}, ("c",)),
    "signed_mass": (SignedMass, {"m": "m"}, ("m",)),
    "cubic_spring": (CubicSpring, {"k": "k", "k3": "k3", "k5": "k5"}, ("k3",)),
    "backlash": (Backlash, {"k": "k", "gap": "gap"}, ("k", "gap")),
    "friction": (Friction, {"force": "force_", "v_eps": "v_eps", "force_neg": "force_neg"}, ("force",)),
    "bouc_wen": (
        BoucWen,
        {k: k for k in ("alpha", "beta", "gamma", "delta", "nu")},
        ("alpha", "beta", "gamma", "delta"),
    ),
    "mr_damper": (
        MRDamper,
        {"i": "current"} | {f.name: f.name for f in fields(MRDamper) if f.name not in ("between", "current")},
        (),
    ),
}


def make_element(type: str, between, **params) -> Element:
    """Build an element from its model-file type name and parameters.

    Parameters
    ----------
    type : str
        A key of :data:`ELEMENT_TYPES`: ``'spring'``, ``'signed_spring'``, ``'damper'``, ``'signed_damper'``, ``'signed_mass'``,
        ``'cubic_spring'``, ``'backlash'``, ``'friction'``, ``'bouc_wen'`` or ``'mr_damper'``.
    between : tuple of (str, str)
        The two ends: two DOF names, or a DOF name and ``"ground"``.
    **params : float
        The element's parameters under their model-file keys (e.g. ``k``, ``c``; ``force``
        and ``force_neg`` for friction, ``i`` for the MR damper's current), in SI units;
        converted to float (a friction's ``force_neg=None`` is passed as None).

    Returns
    -------
    Element
        An instance of the class registered for `type`.

    Raises
    ------
    ValueError
        If `type` is unknown, a parameter is unknown or missing, or a value is non-physical.
    """
    if type not in ELEMENT_TYPES:
        raise ValueError(f"unknown element {type=}; known: {sorted(ELEMENT_TYPES)}")
    cls, keys, required = ELEMENT_TYPES[type]
    for key in params:
        if key not in keys:
            raise ValueError(f"unknown parameter {key!r} for element type {type!r}; known: {sorted(keys)}")
    for key in required:
        if key not in params:
            raise ValueError(f"missing parameter {key!r} for element type {type!r}")
    return cls(between=between, **{keys[k]: None if v is None else float(v) for k, v in params.items()})
