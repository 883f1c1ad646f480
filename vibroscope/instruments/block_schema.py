"""Block schemas through python-control, and the founding paper's PI + correction schema.

A :class:`BlockSchema` is a signal graph: named blocks (``control.TransferFunction`` or
``control.StateSpace``), each reading one named signal and writing another, plus summing
junctions.  From it we obtain the transfer function from any exogenous input (reference,
load disturbance) to *every* named signal of the schema, which is what the founding
paper's "indicial characteristics in all points of the block schema" instrument shows.

:func:`paper_block_schema` is that instrument's schema (paper eq. 4, figures 6-7): a PI
regulator, a first-order correction, a PT2 plant and unity feedback.

References
----------
.. [1] A. Olaru and S. Olaru, "Assisted dynamic behavior optimization with LabVIEW
   instrumentation", Proc. CSIT vol. 1, IACSIT Press, Singapore, 2011, eq. (4).
.. [2] R. M. Murray et al., python-control, ``control.interconnect``,
   https://python-control.readthedocs.io
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import control
import numpy as np

from vibroscope.instruments.lti import BodeResult, StepResult, bode, clean_tf, step_response

__all__ = [
    "Block",
    "Sum",
    "BlockSchema",
    "PI_REGULATOR",
    "CORRECTION",
    "BLOCK_SCHEMA_PLANT",
    "paper_block_schema",
]

# --------------------------------------------------------------------------- schema


@dataclass(frozen=True)
class Block:
    """One LTI block of a schema: ``output = sys * input``.

    Parameters
    ----------
    name : str
        Block name (e.g. ``"regulator"``).
    sys : control.TransferFunction or control.StateSpace
        SISO LTI model of the block.
    input : str
        Name of the signal the block reads.
    output : str
        Name of the signal the block writes (a "named point" of the schema).
    """

    name: str
    sys: object
    input: str
    output: str


@dataclass(frozen=True)
class Sum:
    """A summing junction: ``output = sum(sign * signal)``.

    Parameters
    ----------
    output : str
        Name of the signal written.
    inputs : tuple of str
        Signal names, each optionally prefixed with ``"-"`` for subtraction
        (``("r", "-y")`` is the error of a unity-feedback loop).
    """

    output: str
    inputs: tuple[str, ...]


@dataclass(frozen=True)
class BlockSchema:
    """A block diagram of named SISO LTI blocks and summing junctions.

    Parameters
    ----------
    blocks : tuple of Block
        The dynamic blocks.
    sums : tuple of Sum, optional
        Summing junctions.
    inputs : tuple of str, optional
        Exogenous signals (reference ``"r"``, load disturbance ``"d"``...).  Defaults to
        ``("r",)``.
    name : str, optional
        A title for plots.

    Notes
    -----
    The closed system is built once with :func:`control.interconnect`, using signal names
    for the connections; :meth:`transfer` then returns the SISO transfer function from an
    exogenous input to any named signal.  Series, parallel and feedback arrangements are
    simply particular graphs; :meth:`series`, :meth:`parallel` and :meth:`feedback` build
    them.

    Examples
    --------
    >>> import control
    >>> g = control.tf([1], [1, 1])
    >>> loop = BlockSchema.feedback(g, control.tf([1], [1]))
    >>> round(float(control.dcgain(loop.transfer("y"))), 6)
    0.5
    """

    blocks: tuple[Block, ...]
    sums: tuple[Sum, ...] = ()
    inputs: tuple[str, ...] = ("r",)
    name: str = ""
    _cache: dict = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "blocks", tuple(self.blocks))
        object.__setattr__(self, "sums", tuple(self.sums))
        object.__setattr__(self, "inputs", tuple(self.inputs))
        outs = [b.output for b in self.blocks] + [s.output for s in self.sums]
        if len(set(outs)) != len(outs):
            raise ValueError(f"each signal must be written once, got outputs {outs=}")
        bad = set(outs) & set(self.inputs)
        if bad:
            raise ValueError(f"exogenous inputs {sorted(bad)} are also written by a block or sum")
        known = set(outs) | set(self.inputs)
        for b in self.blocks:
            if b.input not in known:
                raise ValueError(f"block {b.name!r} reads unknown signal {b.input!r}")
        for s in self.sums:
            for sig in s.inputs:
                if sig.lstrip("-+") not in known:
                    raise ValueError(f"sum {s.output!r} reads unknown signal {sig!r}")

    # ---------------------------------------------------------------- builders
    @classmethod
    def series(cls, *systems, names: Sequence[str] | None = None, name: str = "") -> "BlockSchema":
        """Blocks in series ``r -> G1 -> x1 -> G2 -> ... -> y``; the last signal is ``"y"``.

        Parameters
        ----------
        *systems : control.LTI
            The SISO blocks, in signal order.
        names : sequence of str, optional
            Block names, one per system; default ``G1``, ``G2``, ...
        name : str, optional
            The schema's name; default ``""``.

        Returns
        -------
        BlockSchema
            One exogenous input ``"r"``.
        """
        names = list(names) if names is not None else [f"G{i + 1}" for i in range(len(systems))]
        blocks, prev = [], "r"
        for i, (n, g) in enumerate(zip(names, systems)):
            out = "y" if i == len(systems) - 1 else f"x{i + 1}"
            blocks.append(Block(n, g, prev, out))
            prev = out
        return cls(tuple(blocks), (), ("r",), name)

    @classmethod
    def parallel(cls, *systems, names: Sequence[str] | None = None, name: str = "") -> "BlockSchema":
        """Blocks in parallel, each fed by ``"r"``, outputs ``x1..xn`` summed into ``"y"``.

        Parameters
        ----------
        *systems : control.LTI
            The SISO blocks.
        names : sequence of str, optional
            Block names, one per system; default ``G1``, ``G2``, ...
        name : str, optional
            The schema's name; default ``""``.

        Returns
        -------
        BlockSchema
            One exogenous input ``"r"``.
        """
        names = list(names) if names is not None else [f"G{i + 1}" for i in range(len(systems))]
        blocks = tuple(Block(n, g, "r", f"x{i + 1}") for i, (n, g) in enumerate(zip(names, systems)))
        return cls(blocks, (Sum("y", tuple(b.output for b in blocks)),), ("r",), name)

    @classmethod
    def feedback(cls, forward, back=None, *, sign: int = -1, name: str = "") -> "BlockSchema":
        """Feedback loop ``e = r + sign*m``, ``y = forward*e``, ``m = back*y`` (unity if None).

        Parameters
        ----------
        forward : control.LTI
            The forward path, block ``"forward"`` from ``e`` to ``y``.
        back : control.LTI, optional
            The feedback path, block ``"feedback"`` from ``y`` to ``m``; default unity gain.
        sign : int, optional
            Negative (default -1) for negative feedback ``e = r - m``; otherwise ``e = r + m``.
        name : str, optional
            The schema's name; default ``""``.

        Returns
        -------
        BlockSchema
            Exogenous input ``"r"``; signals ``e``, ``y``, ``m``.
        """
        back = control.tf([1.0], [1.0]) if back is None else back
        s = "-m" if sign < 0 else "m"
        return cls(
            (Block("forward", forward, "e", "y"), Block("feedback", back, "y", "m")),
            (Sum("e", ("r", s)),),
            ("r",),
            name,
        )

    # ---------------------------------------------------------------- analysis
    @property
    def signals(self) -> tuple[str, ...]:
        """Every named point: exogenous inputs first, then sums and block outputs in order."""
        return self.inputs + tuple(s.output for s in self.sums) + tuple(b.output for b in self.blocks)

    @property
    def internal_signals(self) -> tuple[str, ...]:
        return tuple(s.output for s in self.sums) + tuple(b.output for b in self.blocks)

    def system(self) -> control.StateSpace:
        """The interconnected MIMO state-space system (inputs ``self.inputs``, outputs every internal signal)."""
        if "sys" not in self._cache:
            syslist = []
            for b in self.blocks:
                g = b.sys
                if isinstance(g, control.TransferFunction):
                    g = control.tf(g.num, g.den, inputs=b.input, outputs=b.output, name=b.name)
                else:
                    g = control.ss(g, inputs=b.input, outputs=b.output, name=b.name)
                syslist.append(g)
            for k, s in enumerate(self.sums):
                ins = [sig[1:] if sig.startswith("+") else sig for sig in s.inputs]
                syslist.append(control.summing_junction(inputs=ins, output=s.output, name=f"sum{k}_{s.output}"))
            self._cache["sys"] = control.interconnect(
                syslist, inplist=list(self.inputs), outlist=list(self.internal_signals), check_unused=False
            )
        return self._cache["sys"]

    def transfer(self, to: str, from_: str | None = None) -> control.TransferFunction:
        """SISO transfer function from exogenous input `from_` (default: the first) to signal `to`.

        Parameters
        ----------
        to : str
            A named point of the schema (see :attr:`signals`).
        from_ : str, optional
            An exogenous input; defaults to ``self.inputs[0]`` (the reference).

        Returns
        -------
        control.TransferFunction
            Cleaned (minimal, monic denominator) transfer function.
        """
        from_ = self.inputs[0] if from_ is None else from_
        if from_ not in self.inputs:
            raise ValueError(f"{from_=} is not an exogenous input of the schema {self.inputs=}")
        if to not in self.signals:
            raise ValueError(f"{to=} is not a signal of the schema {self.signals=}")
        if to in self.inputs:
            return control.tf([1.0 if to == from_ else 0.0], [1.0])
        key = ("tf", to, from_)
        if key not in self._cache:
            sys = self.system()
            i = self.inputs.index(from_)
            o = self.internal_signals.index(to)
            self._cache[key] = clean_tf(sys[o, i])
        return self._cache[key]

    def transfers(self, from_: str | None = None) -> dict[str, control.TransferFunction]:
        """Transfer functions from `from_` to every named point, as a dict keyed by signal name.

        Parameters
        ----------
        from_ : str, optional
            An exogenous input; defaults to ``self.inputs[0]`` (the reference).

        Returns
        -------
        dict of str to control.TransferFunction
            As :meth:`transfer`, for every name of :attr:`signals`.

        Raises
        ------
        ValueError
            If `from_` is not an exogenous input of the schema.
        """
        return {s: self.transfer(s, from_) for s in self.signals}

    def step(self, t, from_: str | None = None, amplitude: float = 1.0) -> dict[str, StepResult]:
        """Indicial (step) responses at every named point to a step of `from_`.

        Parameters
        ----------
        t : array_like
            Time grid in s.
        from_ : str, optional
            Exogenous input stepped (default: the reference).
        amplitude : float
            Step height, in the unit of that input.

        Returns
        -------
        dict of str to StepResult
            The step response at each named point (signal name -> result).
        """
        return {s: step_response(g, t, amplitude=amplitude) for s, g in self.transfers(from_).items()}

    def block_bode(self, frequencies) -> dict[str, BodeResult]:
        """Bode data of each block on its own, keyed by block name.

        Parameters
        ----------
        frequencies : array_like
            Frequencies in Hz.

        Returns
        -------
        dict of str to BodeResult
            :func:`~vibroscope.instruments.lti.bode` of each block's system.
        """
        return {b.name: bode(b.sys, frequencies) for b in self.blocks}

    def forced_response(self, t, u, from_: str | None = None) -> dict[str, np.ndarray]:
        """Responses at every named point to the input history `u` applied at `from_`.

        Parameters
        ----------
        t : array_like
            Time grid in s.
        u : array_like
            Input samples on `t`, in the unit of that input.
        from_ : str, optional
            Exogenous input driven (default: the reference).

        Returns
        -------
        dict of str to ndarray
            The response on `t` at each named point (signal name -> samples).
        """
        return {s: np.asarray(control.forced_response(g, T=t, U=u).outputs, dtype=float).reshape(-1)
                for s, g in self.transfers(from_).items()}


# --------------------------------------------------------------------------- the paper's schema

#: Paper eq. (4) PI regulator ``H_R(s) = 0.9 (9.9 s + 1) / (3 s)`` (dimensionless gain).
PI_REGULATOR = control.tf([0.9 * 9.9, 0.9], [3.0, 0.0])
#: Paper eq. (4) correction ``H_c(s) = 1 / (0.7 s + 1)`` (the paper calls it PDT1; as
#: printed it is a first-order lag PT1, time constant 0.7 s).
CORRECTION = control.tf([1.0], [0.7, 1.0])
#: Plant of the schema: the paper's figure 6 plant is not recoverable from the text; we use
#: a proportional-inertial second-order element (the paper's "PT2" class of robot modules)
#: ``H_p(s) = 1 / (s^2/omega_n^2 + 2 zeta s/omega_n + 1)``, omega_n = 5 rad/s, zeta = 0.7.
BLOCK_SCHEMA_PLANT = control.tf([1.0], [1.0 / 25.0, 2 * 0.7 / 5.0, 1.0])


def paper_block_schema(load: bool = False, *, closed: bool = True, plant=None) -> BlockSchema:
    """The paper's figure 6 block schema: PI regulator, correction, plant, unity feedback.

    Signals (named points): ``r`` reference, ``e = r - y`` error (``r`` itself when
    open), ``u`` regulator output, ``c`` correction output, ``v = c + d`` plant input
    (with the load disturbance ``d``), ``y`` plant output.

    Parameters
    ----------
    load : bool
        Whether the load-disturbance input ``d`` (a force-like signal added at the plant
        input, same unit as ``c``) is an exogenous input of the schema.
    closed : bool
        Unity-feedback closed loop (True) or open loop (False: ``e = r``).
    plant : control.LTI, optional
        Plant model; :data:`BLOCK_SCHEMA_PLANT` by default.

    Returns
    -------
    BlockSchema
        Use ``.transfer(point)`` / ``.step(t)`` for the indicial response at every point,
        ``.step(t, from_="d")`` for the load step.
    """
    plant = BLOCK_SCHEMA_PLANT if plant is None else plant
    blocks = (
        Block("regulator", PI_REGULATOR, "e", "u"),
        Block("correction", CORRECTION, "u", "c"),
        Block("plant", plant, "v", "y"),
    )
    sums = [Sum("e", ("r", "-y") if closed else ("r",))]
    sums.append(Sum("v", ("c", "d") if load else ("c",)))
    inputs = ("r", "d") if load else ("r",)
    title = f"PI + correction + plant, {'closed' if closed else 'open'} loop{', with load' if load else ''}"
    return BlockSchema(blocks, tuple(sums), inputs, title)
