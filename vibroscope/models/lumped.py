"""Lumped multi-DOF models: masses joined by springs, dampers and nonlinear elements.

Equation of motion (linear part)::

    M xddot + C xdot + K x = B_u u

with ``M = diag(m)`` (kg), ``K`` (N/m) and ``C`` (N s/m) assembled from the elements'
linear parts, and force inputs (N) acting on single DOFs. Nonlinear elements (see
:mod:`vibroscope.models.elements`) add forces that :func:`vibroscope.models.simulate.simulate`
integrates in time; the analytic methods here (:meth:`LumpedModel.modes`,
:meth:`LumpedModel.frf`, :meth:`LumpedModel.state_space`) use the linear part only.

References
----------
.. [1] M. Géradin, D. J. Rixen, *Mechanical Vibrations: Theory and Application to
   Structural Dynamics*, 3rd ed., Wiley, 2015 (state-space eigenproblem, FRFs).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, Sequence

import numpy as np

from vibroscope._checks import read_only as _ro

from vibroscope.models.controller import Controller
from vibroscope.models.elements import GROUND, Damper, Element, Spring

__all__ = ["Dof", "Input", "Output", "Modes", "LumpedModel", "demo_model", "demo_model_5dof", "close_modes_model"]

Quantity = Literal["acceleration", "velocity", "displacement"]
QUANTITIES = ("acceleration", "velocity", "displacement")
UNITS = {"acceleration": "m/s^2", "velocity": "m/s", "displacement": "m", "force": "N"}


@dataclass(frozen=True)
class Dof:
    """A degree of freedom: a point mass `mass` (kg) moving along one axis, named `name`.

    Parameters
    ----------
    name : str
        The DOF's name (converted to str); ``"ground"`` is reserved.
    mass : float
        Mass in kg, positive and finite.

    Raises
    ------
    ValueError
        If `mass` is not a positive finite number or `name` is ``"ground"``.
    """

    name: str
    mass: float

    def __post_init__(self) -> None:
        m = float(self.mass)
        if not np.isfinite(m) or m <= 0:
            raise ValueError(f"mass={m} of DOF {self.name!r} must be a positive finite mass in kg")
        if str(self.name) == GROUND:
            raise ValueError(f"{GROUND!r} is reserved and cannot name a DOF")
        object.__setattr__(self, "name", str(self.name))
        object.__setattr__(self, "mass", m)


@dataclass(frozen=True, kw_only=True)
class Input:
    """A force input (N) acting on DOF `dof`.

    Parameters
    ----------
    dof : str
        DOF the force acts on.
    quantity : {"force"}
        Only force inputs are supported.
    channel : str, optional
        Message path of the input in a log (``/actuator/force_cmd.wrench.force.x``).
    saturation : float, optional
        Actuator limit in N: the applied force is ``clip(u, -saturation, saturation)``.
    delay : float
        Input (transport) delay in s, >= 0.
    offset : float
        Constant force bias in N (finite, either sign; default 0.0) added to the logged
        input: the applied force is ``clip(u(t - delay) + offset, -saturation, saturation)``.
        A constant, so it leaves :meth:`LumpedModel.frf` unchanged and keeps a linear
        model linear (affine): the time response adds the static deflection to it.
    saturation_law : {"clip", "tanh"}
        The limit's law: ``"clip"`` (default, a hard limit) or ``"tanh"``, the smooth
        ``saturation * tanh(u / saturation)`` (a limit reached asymptotically, as by an
        amplifier that compresses before it clips). Open-loop inputs only: a closed loop's
        driven input clips.

    Raises
    ------
    ValueError
        If `quantity` is not ``"force"``, `saturation` is not a positive finite force,
        `saturation_law` is not ``"clip"`` or ``"tanh"``, `delay` is negative or not finite,
        or `offset` is not finite.
    """

    dof: str
    quantity: str = "force"
    channel: str | None = None
    saturation: float | None = None
    delay: float = 0.0
    offset: float = 0.0
    saturation_law: str = "clip"

    def __post_init__(self) -> None:
        if self.quantity != "force":
            raise ValueError(f"quantity={self.quantity!r} must be 'force'")
        if self.saturation_law not in ("clip", "tanh"):
            raise ValueError(f"saturation_law={self.saturation_law!r} must be 'clip' or 'tanh'")
        if self.saturation is not None:
            s = float(self.saturation)
            if not np.isfinite(s) or s <= 0:
                raise ValueError(f"saturation={s} must be a positive force in N")
            object.__setattr__(self, "saturation", s)
        d = float(self.delay)
        if not np.isfinite(d) or d < 0:
            raise ValueError(f"delay={d} must be >= 0 s")
        object.__setattr__(self, "delay", d)
        o = float(self.offset)
        if not np.isfinite(o):
            raise ValueError(f"offset={o} must be a finite force in N")
        object.__setattr__(self, "offset", o)

    def saturate(self, x: np.ndarray) -> np.ndarray:
        """A force limited at this input's saturation, by its law.

        Parameters
        ----------
        x : ndarray
            Force samples (N), any shape.

        Returns
        -------
        ndarray
            ``clip(x, -saturation, saturation)`` (``saturation_law = "clip"``) or
            ``saturation * tanh(x / saturation)`` (``"tanh"``), a new array of `x`'s shape;
            `x` itself (as an array) when the input has no saturation.

        References
        ----------
        .. [1] K. J. Astrom, R. M. Murray, *Feedback Systems*, 2008, sec. 3.2 (actuator
           saturation; ``tanh`` as its smooth form).
        """
        x = np.asarray(x, dtype=float)
        if self.saturation is None:
            return x
        if self.saturation_law == "tanh":
            return self.saturation * np.tanh(x / self.saturation)
        return np.clip(x, -self.saturation, self.saturation)


@dataclass(frozen=True)
class Output:
    """A measured response of DOF `dof`: ``quantity`` in acceleration (m/s^2),
    velocity (m/s) or displacement (m), logged as `channel`.

    Parameters
    ----------
    dof : str
        Name of the DOF whose motion is measured.
    quantity : {"acceleration", "velocity", "displacement"}, optional
        The measured quantity, in m/s^2, m/s or m; default ``"acceleration"``.
    channel : str, optional
        Message path of the output in a log; default None (the model derives one from the
        DOF and quantity, see :meth:`LumpedModel.output_channels`).

    Raises
    ------
    ValueError
        If `quantity` is not one of the three.
    """

    dof: str
    quantity: str = "acceleration"
    channel: str | None = None

    def __post_init__(self) -> None:
        if self.quantity not in QUANTITIES:
            raise ValueError(f"quantity={self.quantity!r} must be one of {QUANTITIES}")


@dataclass(frozen=True)
class Modes:
    """Modes of the linear part of a lumped model, sorted by natural frequency.

    Attributes
    ----------
    natural_frequencies : ndarray, shape (n_modes,)
        Undamped natural frequencies ``|lambda| / (2 pi)`` in Hz.
    damping_ratios : ndarray, shape (n_modes,)
        ``-Re(lambda) / |lambda|`` (dimensionless).
    shapes : ndarray of complex, shape (n_modes, n_dofs)
        Displacement mode shapes, each scaled so its largest-modulus entry is exactly 1.
    dofs : tuple of str
        DOF names, the columns of `shapes`.
    eigenvalues : ndarray of complex, shape (n_modes,)
        The state-space eigenvalues ``lambda`` (rad/s) with positive imaginary part.
    """

    natural_frequencies: np.ndarray
    damping_ratios: np.ndarray
    shapes: np.ndarray
    dofs: tuple[str, ...]
    eigenvalues: np.ndarray

    def __iter__(self):
        return iter((self.natural_frequencies, self.damping_ratios, self.shapes))

    def __len__(self) -> int:
        return len(self.natural_frequencies)


@dataclass(frozen=True, kw_only=True)
class LumpedModel:
    """A lumped-mass model: DOFs, elements between them, force inputs and outputs.

    Parameters
    ----------
    dofs : sequence of Dof
        The masses; their order is the order of the DOF vector ``x``.
    elements : sequence of Element
        Springs, dampers and nonlinear elements (:mod:`vibroscope.models.elements`).
    inputs : sequence of Input
        Force inputs (N), the columns of ``B``.
    outputs : sequence of Output
        Responses, the rows of the output equation.
    name : str
        Free label.
    controllers : sequence of Controller, optional
        Discrete controllers closing loops around the model
        (:mod:`vibroscope.models.controller`); default none. Each drives one input; the
        analytic methods (:meth:`modes`, :meth:`frf`, :meth:`state_matrices`) describe the
        open plant, :func:`vibroscope.models.simulate.simulate` the closed loop.

    Raises
    ------
    ValueError
        If names repeat, an element, input, output or controller names an unknown DOF, a
        controller drives an unknown input or one another controller drives, or channels
        repeat.

    Examples
    --------
    Single DOF, 1 kg on 1e4 N/m: natural frequency ``sqrt(k/m) / 2 pi`` = 15.92 Hz.

    >>> m = LumpedModel.chain([1.0], [1e4], [2.0])
    >>> round(float(m.modes().natural_frequencies[0]), 2)
    15.92
    """

    dofs: tuple[Dof, ...]
    elements: tuple[Element, ...] = ()
    inputs: tuple[Input, ...] = ()
    outputs: tuple[Output, ...] = ()
    name: str = ""
    controllers: tuple[Controller, ...] = ()

    def __post_init__(self) -> None:
        dofs = tuple(d if isinstance(d, Dof) else Dof(*d) for d in self.dofs)
        if not dofs:
            raise ValueError("a lumped model needs at least one DOF")
        names = [d.name for d in dofs]
        if len(set(names)) != len(names):
            raise ValueError(f"DOF names repeat: {names=}")
        points = set(self.point_names())
        known = set(names) | {GROUND} | points
        elements = tuple(self.elements)
        for e in elements:
            if not isinstance(e, Element):
                raise TypeError(f"{e!r} is not an Element")
            for end in e.between:
                if end not in known:
                    raise ValueError(f"element {e.type} between {e.between} names unknown DOF {end!r}")
        inputs = tuple(self.inputs)
        outputs = tuple(self.outputs)
        for io in inputs + outputs:
            if io.dof not in names and io.dof not in points:
                raise ValueError(f"{type(io).__name__} on unknown DOF {io.dof!r}; DOFs are {names}"
                                 + (f", points are {sorted(points)}" if points else ""))
        chans = [io.channel for io in inputs + outputs if io.channel is not None]
        controllers = tuple(self.controllers)
        driven = []
        for c in controllers:
            if not isinstance(c, Controller):
                raise TypeError(f"{c!r} is not a Controller")
            if c.dof not in names:
                raise ValueError(f"controller {c.name!r} measures unknown DOF {c.dof!r}; DOFs are {names}")
            j = _input_index(inputs, c.drives)
            if j is None:
                raise ValueError(f"controller {c.name!r} drives={c.drives!r}: no such input (index or channel) "
                                 f"among {len(inputs)} inputs")
            if j in driven:
                raise ValueError(f"controller {c.name!r} drives input {j}, which another controller drives")
            driven.append(j)
            chans += [ch for ch in (c.reference, c.feedforward, c.command_channel) if ch is not None]
        if len({c.name for c in controllers}) != len(controllers):
            raise ValueError(f"controller names repeat: {[c.name for c in controllers]}")
        if len(set(chans)) != len(chans):
            raise ValueError(f"channel names repeat: {chans}")
        object.__setattr__(self, "controllers", controllers)
        object.__setattr__(self, "dofs", dofs)
        object.__setattr__(self, "elements", elements)
        object.__setattr__(self, "inputs", inputs)
        object.__setattr__(self, "outputs", outputs)

    # -- structure ---------------------------------------------------------------------------
    @property
    def n_dofs(self) -> int:
        """Number of DOFs."""
        return len(self.dofs)

    @property
    def dof_names(self) -> tuple[str, ...]:
        """DOF names in order."""
        return tuple(d.name for d in self.dofs)

    def dof_index(self, name: str) -> int:
        """Index of DOF `name` in the DOF vector.

        Parameters
        ----------
        name : str
            A DOF name.

        Returns
        -------
        int
            Its position in :attr:`dofs` (and in the rows of ``M``, ``K``, ``C``).

        Raises
        ------
        KeyError
            If there is no such DOF.
        """
        pos = self.__dict__.get("_dof_pos")
        if pos is None:  # built once per (immutable) model: the matrices ask for every element's ends
            pos = {d.name: i for i, d in enumerate(self.dofs)}
            object.__setattr__(self, "_dof_pos", pos)
        try:
            return pos[name]
        except KeyError:
            raise KeyError(f"no DOF {name!r}; DOFs are {list(self.dof_names)}") from None

    def point_names(self) -> tuple[str, ...]:
        """Names of further points, besides the DOFs, that elements, inputs and outputs may
        name; none for a plain lumped model (see
        :class:`vibroscope.gap.physical.ModalCoordinatesModel`)."""
        return ()

    def point_vector(self, name: str) -> np.ndarray:
        """Displacement of DOF or point `name` as a combination of the DOFs: ``x_name = v @ x``.

        Parameters
        ----------
        name : str
            A DOF name (or a point of :meth:`point_names`).

        Returns
        -------
        ndarray, shape (n_dofs,)
            The unit vector of the DOF for a plain lumped model.

        Raises
        ------
        KeyError
            If there is no such DOF.
        """
        v = np.zeros(self.n_dofs)
        v[self.dof_index(name)] = 1.0
        return v

    def driven_input(self, controller: Controller) -> int:
        """Index of the input `controller` drives.

        Parameters
        ----------
        controller : Controller
            One of :attr:`controllers`.

        Returns
        -------
        int
            Its column of ``B``.

        Raises
        ------
        ValueError
            If it drives no input of this model.
        """
        j = _input_index(self.inputs, controller.drives)
        if j is None:
            raise ValueError(f"controller {controller.name!r} drives={controller.drives!r}: no such input")
        return j

    @property
    def is_linear(self) -> bool:
        """True when every element is linear and no input saturates (an input ``offset``
        keeps the model linear: affine, simulated on the linear path)."""
        return all(e.is_linear for e in self.elements) and all(i.saturation is None for i in self.inputs)

    @property
    def nonlinear_elements(self) -> tuple[Element, ...]:
        """The elements that are not purely linear springs/dampers."""
        return tuple(e for e in self.elements if not e.is_linear)

    def element_vector(self, element: Element) -> np.ndarray:
        """Connectivity ``l`` of `element`, shape (n_dofs,): ``d = l @ x``.

        Parameters
        ----------
        element : Element
            An element whose ends are DOFs of this model or ``"ground"``.

        Returns
        -------
        ndarray, shape (n_dofs,)
            +1 at the first end's DOF, -1 at the second's, 0 elsewhere (nothing for ground).

        Raises
        ------
        KeyError
            If an end names no DOF of the model.
        """
        lv = np.zeros(self.n_dofs)
        a, b = element.between
        if a != GROUND:
            lv += self.point_vector(a)
        if b != GROUND:
            lv -= self.point_vector(b)
        return lv

    def input_channels(self) -> list[str]:
        """Channel names of the inputs (default ``/actuator/<dof>_force.wrench.force.x``)."""
        return [i.channel or f"/actuator/{i.dof}_force.wrench.force.x" for i in self.inputs]

    def output_channels(self) -> list[str]:
        """Channel names of the outputs (defaults derived from DOF and quantity)."""
        default = {
            "acceleration": "/imu/{}.linear_acceleration.x",
            "velocity": "/sim/{}.velocity.x",
            "displacement": "/sim/{}.displacement.x",
        }
        return [o.channel or default[o.quantity].format(o.dof) for o in self.outputs]

    # -- linear matrices -----------------------------------------------------------------------
    @property
    def M(self) -> np.ndarray:
        """Mass matrix (kg), shape (n_dofs, n_dofs): the DOFs' masses on the diagonal, plus each
        :class:`~vibroscope.models.SignedMass` element's ``m l l^T`` (``l`` its
        :meth:`element_vector`)."""
        return _ro(self._assembled("linear_mass", np.diag([d.mass for d in self.dofs])))

    @property
    def M_inv(self) -> np.ndarray:
        """Inverse of the mass matrix (1/kg), shape (n_dofs, n_dofs): ``diag(1 / m)`` for a
        diagonal :attr:`M`, else its matrix inverse.

        Raises
        ------
        numpy.linalg.LinAlgError
            If :attr:`M` is singular.
        """
        M = np.asarray(self.M)
        if not any(e.linear_mass for e in self.elements):
            return _ro(np.diag(1.0 / np.diag(M)))
        return _ro(np.linalg.inv(M))

    @property
    def K(self) -> np.ndarray:
        """Stiffness matrix (N/m) of the elements' linear parts, shape (n_dofs, n_dofs)."""
        return _ro(self._assembled("linear_stiffness"))

    @property
    def C(self) -> np.ndarray:
        """Damping matrix (N s/m) of the elements' linear parts, shape (n_dofs, n_dofs)."""
        return _ro(self._assembled("linear_damping"))

    def _assembled(self, attr: str, start: np.ndarray | None = None) -> np.ndarray:
        """`start` (default zeros) plus each element's ``getattr(e, attr) l l^T``."""
        A = np.zeros((self.n_dofs, self.n_dofs)) if start is None else start
        for e in self.elements:
            v = getattr(e, attr)
            if v:
                lv = self.element_vector(e)
                A += v * np.outer(lv, lv)
        return A

    @property
    def B(self) -> np.ndarray:
        """Force distribution matrix, shape (n_dofs, n_inputs): ``f = B u``."""
        B = np.zeros((self.n_dofs, len(self.inputs)))
        for j, i in enumerate(self.inputs):
            B[:, j] = self.point_vector(i.dof)
        return _ro(B)

    def state_matrices(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """First-order form ``q = [x, xdot]`` (2 n_dofs): ``qdot = A q + Bq u``, ``y = Cq q + Dq u``.

        Outputs are the configured ones (acceleration rows use ``xddot = -M^-1 (K x + C xdot) + M^-1 B u``).

        Returns
        -------
        A : ndarray, shape (2 n, 2 n)
        B : ndarray, shape (2 n, n_inputs)
        C : ndarray, shape (n_outputs, 2 n)
        D : ndarray, shape (n_outputs, n_inputs)
        """
        n = self.n_dofs
        Minv = np.asarray(self.M_inv)
        A = np.zeros((2 * n, 2 * n))
        A[:n, n:] = np.eye(n)
        A[n:, :n] = -Minv @ self.K
        A[n:, n:] = -Minv @ self.C
        Bq = np.zeros((2 * n, len(self.inputs)))
        Bq[n:] = Minv @ self.B
        Cq = np.zeros((len(self.outputs), 2 * n))
        Dq = np.zeros((len(self.outputs), len(self.inputs)))
        for r, o in enumerate(self.outputs):
            v = self.point_vector(o.dof)
            if o.quantity == "displacement":
                Cq[r, :n] = v
            elif o.quantity == "velocity":
                Cq[r, n:] = v
            else:
                Cq[r] = v @ A[n:]
                Dq[r] = v @ Bq[n:]
        return A, Bq, Cq, Dq

    # -- analysis ------------------------------------------------------------------------------
    def modes(self) -> Modes:
        """Complex modes of the linear part from the state-space eigenproblem.

        Returns
        -------
        Modes
            Natural frequencies (Hz), damping ratios and complex displacement shapes
            ``(n_modes, n_dofs)``, sorted by frequency. Only oscillatory modes (eigenvalues
            with positive imaginary part) are returned; overdamped or rigid-body modes are
            left out.

        Notes
        -----
        With eigenvalues ``lambda_r`` of ``A = [[0, I], [-M^-1 K, -M^-1 C]]``:
        ``f_r = |lambda_r| / 2 pi`` and ``zeta_r = -Re(lambda_r) / |lambda_r|``. For
        proportional damping these equal the undamped eigenfrequencies
        ``sqrt(eig(K, M)) / 2 pi`` exactly.
        """
        n = self.n_dofs
        A = self.state_matrices()[0]
        lam, vec = np.linalg.eig(A)
        keep = lam.imag > 1e-9 * np.maximum(np.abs(lam), 1.0)
        lam, vec = lam[keep], vec[:n, keep]
        wn = np.abs(lam)
        order = np.argsort(wn)
        lam, vec, wn = lam[order], vec[:, order], wn[order]
        shapes = vec.T.copy()
        for r in range(shapes.shape[0]):
            shapes[r] /= shapes[r, np.argmax(np.abs(shapes[r]))]
        return Modes(_ro(wn / (2 * np.pi)), _ro(-lam.real / wn), _ro(shapes), self.dof_names, _ro(lam))

    def frf(self, frequencies, quantity: Quantity | None = "acceleration") -> np.ndarray:
        """Analytic frequency response of the linear part, outputs by inputs.

        ``H(w) = s(w) (K - w^2 M + j w C)^-1`` restricted to the output rows and input
        columns, with ``s = -w^2`` (accelerance, (m/s^2)/N), ``j w`` (mobility, (m/s)/N) or
        1 (receptance, m/N), times ``exp(-j w tau)`` for an input delay ``tau``.

        Parameters
        ----------
        frequencies : array_like, shape (n_f,)
            Frequencies in Hz.
        quantity : {"acceleration", "velocity", "displacement"} or None
            Response quantity for every output; None uses each output's configured quantity.

        Returns
        -------
        H : ndarray of complex, shape (n_f, n_outputs, n_inputs)

        Raises
        ------
        ValueError
            If `quantity` is not one of the allowed values.
        """
        f = np.atleast_1d(np.asarray(frequencies, dtype=float))
        w = 2 * np.pi * f
        S = self.output_factors(f, quantity)
        B = self.B
        G = np.linalg.solve(self.dynamic_stiffness(f), np.broadcast_to(B, (len(f),) + B.shape))  # (n_f, n_dofs, n_in)
        H = np.einsum("od,fdi->foi", self.output_rows(), G) * S[:, :, None]
        delays = np.array([i.delay for i in self.inputs])
        if np.any(delays):
            H *= np.exp(-1j * w[:, None] * delays[None, :])[:, None, :]
        return H

    def dynamic_stiffness(self, frequencies) -> np.ndarray:
        """The dynamic stiffness ``Z(w) = K - w^2 M + j w C`` of the linear part.

        Parameters
        ----------
        frequencies : array_like, shape (n_f,)
            Frequencies in Hz.

        Returns
        -------
        Z : ndarray of complex, shape (n_f, n_dofs, n_dofs)
            N/m (N/rad for rotational DOFs).
        """
        w = 2 * np.pi * np.atleast_1d(np.asarray(frequencies, dtype=float))
        return self.K[None] - (w**2)[:, None, None] * self.M[None] + 1j * w[:, None, None] * self.C[None]

    def output_rows(self) -> np.ndarray:
        """The outputs' point vectors: the rows that map the DOFs' motion to each output.

        Returns
        -------
        rows : ndarray, shape (n_outputs, n_dofs)
            Dimensionless (a point's share of each DOF's motion).
        """
        return np.array([self.point_vector(o.dof) for o in self.outputs]).reshape(len(self.outputs), self.n_dofs)

    def output_factors(self, frequencies, quantity: Quantity | None = None) -> np.ndarray:
        """Each output's factor from receptance to its quantity: ``-w^2`` (acceleration), ``j w``
        (velocity) or 1 (displacement).

        Parameters
        ----------
        frequencies : array_like, shape (n_f,)
            Frequencies in Hz.
        quantity : {"acceleration", "velocity", "displacement"} or None
            Quantity for every output; None uses each output's configured quantity.

        Returns
        -------
        S : ndarray of complex, shape (n_f, n_outputs)

        Raises
        ------
        ValueError
            If `quantity` is not one of the allowed values.
        """
        if quantity is not None and quantity not in QUANTITIES:
            raise ValueError(f"{quantity=} must be one of {QUANTITIES} or None")
        w = 2 * np.pi * np.atleast_1d(np.asarray(frequencies, dtype=float))
        S = np.ones((w.size, len(self.outputs)), complex)
        for r, o in enumerate(self.outputs):
            q = quantity or o.quantity
            if q == "acceleration":
                S[:, r] = -(w**2)
            elif q == "velocity":
                S[:, r] = 1j * w
        return S

    def state_space(self):
        """The linear part as a :class:`control.StateSpace` (state ``[x, xdot]``).

        Inputs are the force inputs (N), outputs the configured outputs. Input delays are not
        represented (use :meth:`frf`, which includes them).
        """
        import control

        A, B, C, D = self.state_matrices()
        return control.ss(
            A,
            B,
            C,
            D,
            inputs=[_signal_name(c) for c in self.input_channels()],
            outputs=[_signal_name(c) for c in self.output_channels()],
            states=[f"x_{d}" for d in self.dof_names] + [f"v_{d}" for d in self.dof_names],
        )

    # -- construction --------------------------------------------------------------------------
    @classmethod
    def chain(
        cls,
        masses: Sequence[float],
        springs: Sequence[float],
        dampers: Sequence[float] | float = 0.0,
        *,
        input_dof: int = 0,
        input_channel: str = "/actuator/force.wrench.force.x",
        output_quantity: Quantity = "acceleration",
        nonlinear: Sequence[Element] = (),
        name: str = "chain",
    ) -> "LumpedModel":
        """Fixed-free chain ground–m1–m2–…–mn of masses (kg), springs (N/m) and dampers (N s/m).

        Spring and damper ``i`` join ``m{i+1}`` to ``m{i}`` (ground for i = 0). The force
        input acts on DOF index `input_dof`; every DOF has an output (acceleration by default)
        named ``/imu/m{k}.linear_acceleration.x`` (k from 1).

        Parameters
        ----------
        masses : sequence of float
            Masses in kg, m1 first; their count n sets the number of DOFs (named ``m1`` …
            ``mn``).
        springs : sequence of float or float
            Stiffnesses in N/m, length n (or a scalar, broadcast to all n).
        dampers : sequence of float or float, optional
            Viscous damping coefficients in N s/m, length n or a scalar; default 0.0. A zero
            entry adds no damper.
        input_dof : int, optional
            Index (from 0) of the DOF the force input acts on; default 0 (m1).
        input_channel : str, optional
            Message path of the force input; default ``"/actuator/force.wrench.force.x"``.
        output_quantity : {"acceleration", "velocity", "displacement"}, optional
            Quantity measured at every DOF; default ``"acceleration"``. The output channels are
            ``/imu/m{k}.linear_acceleration.x``, ``/imu/m{k}.velocity.x`` or
            ``/imu/m{k}.displacement.x``.
        nonlinear : sequence of Element, optional
            Further elements appended after the chain's springs and dampers; default none.
        name : str, optional
            The model's name; default ``"chain"``.

        Returns
        -------
        LumpedModel

        Raises
        ------
        ValueError
            If `springs` or `dampers` cannot be broadcast to the length of `masses`, or
            `input_dof` is not in ``range(n)``.
        """
        masses = list(np.atleast_1d(np.asarray(masses, dtype=float)))
        n = len(masses)
        springs = list(np.broadcast_to(np.asarray(springs, dtype=float), (n,)))
        dampers = list(np.broadcast_to(np.asarray(dampers, dtype=float), (n,)))
        names = [f"m{k + 1}" for k in range(n)]
        dofs = [Dof(nm, m) for nm, m in zip(names, masses)]
        elements: list[Element] = []
        for i in range(n):
            other = GROUND if i == 0 else names[i - 1]
            elements.append(Spring((names[i], other), k=springs[i]))
            if dampers[i]:
                elements.append(Damper((names[i], other), c=dampers[i]))
        elements.extend(nonlinear)
        if not 0 <= input_dof < n:
            raise ValueError(f"{input_dof=} must index one of the {n} DOFs")
        inputs = [Input(dof=names[input_dof], channel=input_channel)]
        prefix = {"acceleration": "linear_acceleration", "velocity": "velocity", "displacement": "displacement"}
        outputs = [
            Output(nm, output_quantity, f"/imu/{nm}.{prefix[output_quantity]}.x") for nm in names
        ]
        return cls(dofs=tuple(dofs), elements=tuple(elements), inputs=tuple(inputs), outputs=tuple(outputs),
                   name=name)

    def replace(self, **changes) -> "LumpedModel":
        """A copy with fields replaced (``dofs``, ``elements``, ``inputs``, ``outputs``, ``name``,
        ``controllers``)."""
        from dataclasses import replace

        return replace(self, **changes)


def _input_index(inputs, drives) -> int | None:
    """The input index `drives` names (an index, or an input's channel); None if none."""
    if isinstance(drives, int) and not isinstance(drives, bool):
        return drives if 0 <= drives < len(inputs) else None
    for j, i in enumerate(inputs):
        if i.channel == drives:
            return j
    return None


def _signal_name(channel: str) -> str:
    """python-control forbids '.' in signal names: ``/imu/m1.linear_acceleration.x`` ->
    ``/imu/m1:linear_acceleration:x``."""
    return channel.replace(".", ":")


def demo_model() -> LumpedModel:
    """The 3-DOF demo structure used by ``vibroscope demo``.

    Chain ground–m1–m2–m3 with masses 2, 1.5, 1 kg, springs 1e5, 8e4, 5e4 N/m and dampers
    giving 1–3 % modal damping; modes near 18.4, 41.9 and 60.4 Hz. Force input on m3
    (``/actuator/force.wrench.force.x``), accelerations of all three masses.
    """
    return LumpedModel.chain(
        [2.0, 1.5, 1.0],
        [1.0e5, 8.0e4, 5.0e4],
        [20.0, 12.0, 8.0],
        input_dof=2,
        name="demo 3-DOF",
    )


def demo_model_5dof() -> LumpedModel:
    """A 5-DOF chain (masses 1.0–0.6 kg, springs 2e5–6e4 N/m, light damping) with modes
    between about 20 and 118 Hz (0.5–3 % damping), force input on the last mass."""
    return LumpedModel.chain(
        [1.0, 0.9, 0.8, 0.7, 0.6],
        [2.0e5, 1.6e5, 1.2e5, 9.0e4, 6.0e4],
        [16.0, 12.0, 10.0, 8.0, 6.0],
        input_dof=4,
        name="demo 5-DOF",
    )


def close_modes_model() -> LumpedModel:
    """A 5-DOF chain with two close, overlapping modes: the modal identification benchmark.

    Fixed-free chain ground–m1–…–m5 (masses 1.0–0.039 kg, springs 70 297–4 855 N/m, chain dampers),
    force on the tip mass m5, accelerations of all masses. Modes near 12.0, 27.0, 45.0, 45.9 and
    80.0 Hz, all with ζ ≈ 1 % (non-proportional damping: complex modes); modes 3 and 4 are 2.0 %
    apart with a modal overlap ``(ζ₃f₃ + ζ₄f₄) / (f₄ − f₃) ≈ 1``. Designed by a Jacobi inverse
    eigenvalue problem (Gladwell, Inverse Problems in Vibration, 2004, ch. 4) for those frequencies
    with every mode large at m5, then tuned by least squares on :meth:`LumpedModel.modes`.
    """
    return LumpedModel.chain(
        [1.0, 0.5360, 0.2978, 0.07561, 0.03865],
        [70297.0, 8340.0, 5413.6, 8320.8, 4854.9],
        [1.587, 3.705, 0.0, 0.6185, 0.1005],
        input_dof=4,
        name="close modes 5-DOF",
    )
