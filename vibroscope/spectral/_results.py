"""Result containers of the spectral analysis: small frozen dataclasses that carry their axis and
their settings, unpack as tuples, and plot lazily."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Iterator, Literal, Sequence

import numpy as np

from vibroscope._checks import UnpacksAsTuple, axis_summary, check_option, names_summary, read_only
from vibroscope.spectral.kinds import FRF_KIND_TABLE, FRF_KINDS

__all__ = ["Spectrum", "CrossSpectralMatrix", "FRF", "Spectrogram", "Coherence", "MultipleCoherence", "FRF_KINDS"]




def power_units(units: Sequence[str], scaling: str) -> tuple[str, ...]:
    """Units of auto-spectra: ``(u)^2/Hz`` or ``(u)^2``; dimensionless channels give ``1/Hz`` or ``1``."""
    return tuple((f"({u})^2" if u else "1") + ("/Hz" if scaling == "density" else "") if (u or scaling == "spectrum")
                 else "1/Hz" for u in units)


def channel_index(channels: Sequence[str], channel: str | int) -> int:
    """Position of a channel given by name or by (possibly negative) index.

    Raises
    ------
    KeyError
        If the name is not one of `channels` or the index is out of range; the message names the
        valid channels.
    """
    n = len(channels)
    if isinstance(channel, (int, np.integer)) and not isinstance(channel, bool):
        if -n <= channel < n:
            return int(channel) % n
        raise KeyError(f"no channel {channel!r} (index out of range 0..{n - 1}); channels are {list(channels)}")
    try:
        return list(channels).index(channel)
    except ValueError:
        raise KeyError(f"no channel {channel!r}; channels are {list(channels)}") from None


@dataclass(frozen=True, eq=False, kw_only=True)
class Spectrum:
    """Real spectra of several channels on one frequency axis.

    Attributes
    ----------
    frequencies : ndarray, shape (n_freqs,)
        Frequency axis in Hz.
    values : ndarray, shape (n_channels, n_freqs)
        Power spectral density (unit²/Hz, ``scaling='density'``), power spectrum (unit²,
        ``'spectrum'``) or peak amplitude spectrum (unit, ``'amplitude'``).
    channels : tuple of str
        Channel names (message paths).
    units : tuple of str
        Units of `values`, one per channel (e.g. ``"(m/s^2)^2/Hz"``).
    scaling : {'density', 'spectrum', 'amplitude'}
        What `values` are.
    settings : dict
        ``fs``, ``nperseg``, ``noverlap``, ``nfft``, ``window``, ``detrend``, ``n_averages`` (the
        smallest count over the channels) and, when segments were skipped for missing samples,
        ``n_segments`` (all segments of the record).
    n_averages : ndarray of int, shape (n_channels,), or None
        Segments averaged per channel: those free of NaN/Inf (Welch estimates); None when not
        from Welch averaging.

    Examples
    --------
    It unpacks like scipy's ``(f, Pxx)``:

    >>> import numpy as np
    >>> from vibroscope.spectral import welch
    >>> f, p = welch(np.random.default_rng(0).standard_normal(4096), fs=100.0, nperseg=256)
    >>> f.shape, p.shape
    ((129,), (1, 129))
    """

    frequencies: np.ndarray
    values: np.ndarray
    channels: tuple[str, ...]
    units: tuple[str, ...]
    scaling: Literal["density", "spectrum", "amplitude"]
    settings: dict = field(default_factory=dict)
    n_averages: np.ndarray | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "frequencies", read_only(self.frequencies, float))
        object.__setattr__(self, "values", read_only(np.atleast_2d(self.values), float))
        object.__setattr__(self, "channels", tuple(self.channels))
        object.__setattr__(self, "units", tuple(self.units))
        if self.n_averages is not None:
            object.__setattr__(self, "n_averages", read_only(self.n_averages, np.int64))

    def __iter__(self) -> Iterator[np.ndarray]:
        return iter((self.frequencies, self.values))

    def __getitem__(self, channel: str | int) -> np.ndarray:
        """Values of one channel (name or index), shape (n_freqs,).

        Raises
        ------
        KeyError
            If there is no such channel; the message names the valid ones.
        """
        return self.values[channel_index(self.channels, channel)]

    def __repr__(self) -> str:
        return (f"Spectrum({len(self.channels)} channels {names_summary(self.channels)}, "
                f"{axis_summary(self.frequencies)}, scaling={self.scaling!r})")

    @property
    def df(self) -> float:
        """Frequency resolution in Hz."""
        return float(self.frequencies[1] - self.frequencies[0])

    def rms(self) -> np.ndarray:
        """RMS of each channel from the integral of a density, shape (n_channels,).

        Returns
        -------
        ndarray
            RMS per channel in the signal unit, shape (n_channels,).

        Raises
        ------
        ValueError
            If the spectrum is not a density.
        """
        if self.scaling != "density":
            raise ValueError(f"RMS by integration needs scaling='density', not {self.scaling=}")
        return np.sqrt(np.sum(self.values, axis=-1) * self.df)

    def plot(self, ax=None, *, db: bool = False, channels=None):
        """Plot on a log (or dB) axis; imports matplotlib lazily. Returns the Axes.

        Parameters
        ----------
        ax : matplotlib.axes.Axes, optional
            Axes to draw on; a new figure when None.
        db : bool, optional
            Plot in dB on a linear axis instead of the values on a log axis; default False.
        channels : sequence of str or int, optional
            Channels to plot (names or indices); all when None.

        Returns
        -------
        matplotlib.axes.Axes
            See :func:`vibroscope.viewers.figures.plot_spectrum`.
        """
        from vibroscope._plotting import draw

        return draw("plot_spectrum", self, ax=ax, db=db, channels=channels)


@dataclass(frozen=True, eq=False, kw_only=True)
class CrossSpectralMatrix:
    """The one-sided cross-spectral matrix of several channels.

    Attributes
    ----------
    frequencies : ndarray, shape (n_freqs,)
        Frequency axis in Hz.
    G : ndarray, complex, shape (n_freqs, n_channels, n_channels)
        ``G[f, i, j]`` = one-sided cross-spectrum of channels i and j with scipy's convention
        ``conj(X_i)·X_j`` (so ``G[:, i, j]`` equals ``scipy.signal.csd(x_i, x_j)``); Hermitian in
        (i, j); the diagonal is the auto-spectra (real, ≥ 0).
    channels, units : tuple of str
        Channel names and units; ``G[f, i, j]`` has unit ``units[i]·units[j]/Hz`` (density).
    scaling : {'density', 'spectrum'}
    settings : dict
        ``fs``, ``nperseg``, ``noverlap``, ``nfft``, ``window``, ``detrend``, ``n_averages`` (the
        smallest count over the pairs) and, when segments were skipped for missing samples,
        ``n_segments`` (all segments of the record).
    n_averages : ndarray of int, shape (n_channels, n_channels), or None
        Segments averaged for each pair: those over which both channels are finite. Each
        ``G[:, i, j]`` is normalised by its own count, so with unequal counts (missing samples)
        entries of `G` are estimated from different segment sets (and `G` need not be positive
        semi-definite). None when unknown (e.g. a matrix assembled by hand).
    """

    frequencies: np.ndarray
    G: np.ndarray
    channels: tuple[str, ...]
    units: tuple[str, ...]
    scaling: Literal["density", "spectrum"]
    settings: dict = field(default_factory=dict)
    n_averages: np.ndarray | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "frequencies", read_only(self.frequencies, float))
        object.__setattr__(self, "G", read_only(self.G, complex))
        object.__setattr__(self, "channels", tuple(self.channels))
        object.__setattr__(self, "units", tuple(self.units))
        if self.n_averages is not None:
            object.__setattr__(self, "n_averages", read_only(self.n_averages, np.int64))

    def __iter__(self) -> Iterator[np.ndarray]:
        return iter((self.frequencies, self.G))

    def __repr__(self) -> str:
        return (f"CrossSpectralMatrix({self.n_channels}×{self.n_channels} channels {names_summary(self.channels)}, "
                f"{axis_summary(self.frequencies)}, scaling={self.scaling!r})")

    @property
    def n_channels(self) -> int:
        """Number of channels."""
        return self.G.shape[1]

    def index(self, channel: str | int) -> int:
        """Index of a channel given by name or position (negative positions count from the end).

        Parameters
        ----------
        channel : str or int
            A name of `channels`, or a position.

        Returns
        -------
        int
            The non-negative index.

        Raises
        ------
        KeyError
            If the name is not one of `channels` or the position is out of range; the message
            names the valid channels.
        """
        return channel_index(self.channels, channel)

    def psd(self) -> Spectrum:
        """The auto-spectra (diagonal) as a :class:`Spectrum`."""
        vals = np.real(np.einsum("fii->if", self.G))
        units = power_units(self.units, self.scaling)
        n_avg = None if self.n_averages is None else np.diag(self.n_averages)
        return Spectrum(frequencies=self.frequencies, values=vals, channels=self.channels, units=units,
                        scaling=self.scaling, settings=dict(self.settings), n_averages=n_avg)

    def select(self, channels) -> "CrossSpectralMatrix":
        """The sub-matrix of `channels` (names or indices), in that order.

        Parameters
        ----------
        channels : sequence of str or int
            The channels to keep, by name or position (:meth:`index`).

        Returns
        -------
        CrossSpectralMatrix

        Raises
        ------
        KeyError
            As :meth:`index`.
        """
        idx = [self.index(c) for c in channels]
        return CrossSpectralMatrix(
            frequencies=self.frequencies,
            G=self.G[:, idx][:, :, idx],
            channels=[self.channels[i] for i in idx],
            units=[self.units[i] for i in idx],
            scaling=self.scaling,
            settings=dict(self.settings),
            n_averages=None if self.n_averages is None else self.n_averages[np.ix_(idx, idx)],
        )

    def band(self, fmin: float, fmax: float) -> "CrossSpectralMatrix":
        """The matrix restricted to ``fmin <= f <= fmax`` (Hz).

        Parameters
        ----------
        fmin, fmax : float
            Band edges in Hz, both included.

        Returns
        -------
        CrossSpectralMatrix

        Raises
        ------
        ValueError
            If ``fmin > fmax``.
        """
        if fmin > fmax:
            raise ValueError(f"{fmin=} Hz must not exceed {fmax=} Hz: swap them")
        m = (self.frequencies >= fmin) & (self.frequencies <= fmax)
        return CrossSpectralMatrix(frequencies=self.frequencies[m], G=self.G[m], channels=self.channels,
                                   units=self.units, scaling=self.scaling, settings=dict(self.settings),
                                   n_averages=self.n_averages)


@dataclass(frozen=True, eq=False, kw_only=True)
class FRF:
    """Frequency response function estimate ``H[f, output, input]``.

    Attributes
    ----------
    frequencies : ndarray, shape (n_freqs,)
        Frequency axis in Hz.
    H : ndarray, complex, shape (n_freqs, n_outputs, n_inputs)
        The FRF: output spectrum per unit input spectrum.
    coherence : ndarray, shape (n_freqs, n_outputs)
        Ordinary coherence γ² with the input for one input; multiple coherence with all inputs
        otherwise. NaN where undefined.
    inputs, outputs : tuple of str
        Channel names.
    estimator : {'H1', 'H2', 'Hv', 'periodic', 'lsfd', 'analytic', 'unknown'}
    kind : {'accelerance', 'mobility', 'receptance'} or None
        The response quantity per unit force when known (outputs accelerations / velocities /
        displacements and inputs forces); None for a generic output/input ratio.
    units : str
        Units of `H` (e.g. ``"m/s^2/N"``).
    settings : dict
        The spectral settings it was estimated with.
    """

    frequencies: np.ndarray
    H: np.ndarray
    coherence: np.ndarray
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    estimator: str
    kind: str | None = None
    units: str = ""
    settings: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "frequencies", read_only(self.frequencies, float))
        object.__setattr__(self, "H", read_only(self.H, complex))
        object.__setattr__(self, "coherence", read_only(self.coherence, float))
        object.__setattr__(self, "inputs", tuple(self.inputs))
        object.__setattr__(self, "outputs", tuple(self.outputs))

    def __iter__(self) -> Iterator[np.ndarray]:
        return iter((self.frequencies, self.H, self.coherence))

    def __repr__(self) -> str:
        kind = f", kind={self.kind!r}" if self.kind else ""
        return (f"FRF({self.estimator}, {len(self.outputs)} outputs {names_summary(self.outputs)} per "
                f"{len(self.inputs)} inputs {names_summary(self.inputs)}, {axis_summary(self.frequencies)}{kind})")

    @property
    def magnitude_db(self) -> np.ndarray:
        """``20 log10 |H|`` (dB re 1 unit), shape like `H`."""
        with np.errstate(divide="ignore"):
            return 20 * np.log10(np.abs(self.H))

    @property
    def phase_deg(self) -> np.ndarray:
        """Phase of `H` in degrees, wrapped to (−180, 180]."""
        return np.degrees(np.angle(self.H))

    def to(self, kind: str) -> "FRF":
        """Convert between accelerance, mobility and receptance by powers of ``jω``.

        ``mobility = accelerance / (jω)``, ``receptance = accelerance / (jω)²``; the 0 Hz bin of a
        division becomes NaN.

        Parameters
        ----------
        kind : {'accelerance', 'mobility', 'receptance'}
            The FRF kind to convert to.

        Returns
        -------
        FRF
            With the new `kind` and its units; frequencies, coherence and settings unchanged.

        Raises
        ------
        ValueError
            If this FRF's kind is unknown (None) or `kind` is not one of :data:`FRF_KINDS`.
        """
        check_option("kind", kind, FRF_KINDS)
        if self.kind is None:
            raise ValueError("this FRF has no known kind (accelerance/mobility/receptance) to convert from")
        p = FRF_KIND_TABLE[kind].power - FRF_KIND_TABLE[self.kind].power
        jw = 2j * np.pi * self.frequencies
        with np.errstate(divide="ignore", invalid="ignore"):
            fac = jw**p
            if p < 0:
                fac[self.frequencies == 0] = np.nan
        H = self.H * fac[:, None, None]
        return FRF(frequencies=self.frequencies, H=H, coherence=self.coherence, inputs=self.inputs,
                   outputs=self.outputs, estimator=self.estimator, kind=kind, units=FRF_KIND_TABLE[kind].unit,
                   settings=dict(self.settings))

    def plot(self, *, output=0, input=0, fig=None):
        """Bode-style figure (magnitude dB, phase, coherence); imports matplotlib lazily. Returns the Figure.

        Parameters
        ----------
        output, input : str or int, optional
            Which response and which excitation (names or indices); default 0 each.
        fig : matplotlib.figure.Figure, optional
            Figure to draw in (cleared); a new one when None.

        Returns
        -------
        matplotlib.figure.Figure
            See :func:`vibroscope.viewers.figures.plot_frf`.
        """
        from vibroscope._plotting import draw

        return draw("plot_frf", self, output=output, input=input, fig=fig)


@dataclass(frozen=True, eq=False, kw_only=True)
class Spectrogram:
    """Short-time spectra of several channels.

    Attributes
    ----------
    frequencies : ndarray, shape (n_freqs,)
        Hz.
    times : ndarray, shape (n_times,)
        Segment centres in s from the record start.
    values : ndarray, shape (n_channels, n_freqs, n_times)
        PSD (unit²/Hz) or power spectrum (unit²) per segment.
    channels, units : tuple of str
    scaling : {'density', 'spectrum'}
    settings : dict
    """

    frequencies: np.ndarray
    times: np.ndarray
    values: np.ndarray
    channels: tuple[str, ...]
    units: tuple[str, ...]
    scaling: str
    settings: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "frequencies", read_only(self.frequencies, float))
        object.__setattr__(self, "times", read_only(self.times, float))
        object.__setattr__(self, "values", read_only(self.values, float))

    def __iter__(self) -> Iterator[np.ndarray]:
        return iter((self.frequencies, self.times, self.values))

    def __repr__(self) -> str:
        t = self.times
        span = f"{t.size} times, {t[0]:.4g}–{t[-1]:.4g} s" if t.size else "0 times"
        return (f"Spectrogram({len(self.channels)} channels {names_summary(self.channels)}, "
                f"{axis_summary(self.frequencies)}, {span}, scaling={self.scaling!r})")


@dataclass(frozen=True, eq=False)
class Coherence(UnpacksAsTuple):
    """Ordinary coherence of every channel pair (:func:`~vibroscope.spectral.coherence`).

    Unpacks like the tuple ``(frequencies, gamma2)`` that scipy's ``coherence`` returns.

    Attributes
    ----------
    frequencies : ndarray, shape (n_freqs,)
        Hz.
    gamma2 : ndarray, shape (n_freqs, n_channels, n_channels)
        ``γ²_ij = |G_ij|² / (G_ii G_jj)`` ∈ [0, 1] (dimensionless); NaN where a channel has no power.
    channels : tuple of str
        Channel names.
    settings : dict
        The Welch settings of the cross-spectral matrix.
    """

    frequencies: np.ndarray
    gamma2: np.ndarray
    channels: tuple[str, ...] = ()
    settings: dict = field(default_factory=dict)

    _tuple_fields = ("frequencies", "gamma2")

    def __post_init__(self) -> None:
        object.__setattr__(self, "frequencies", read_only(self.frequencies, float))
        object.__setattr__(self, "gamma2", read_only(self.gamma2, float))
        object.__setattr__(self, "channels", tuple(self.channels))

    def __repr__(self) -> str:
        return f"Coherence({len(self.channels)} channels {names_summary(self.channels)}, {axis_summary(self.frequencies)})"


@dataclass(frozen=True, eq=False)
class MultipleCoherence(UnpacksAsTuple):
    """Multiple coherence of each output with all inputs together
    (:func:`~vibroscope.spectral.multiple_coherence`); unpacks as ``(frequencies, gamma2)``.

    Attributes
    ----------
    frequencies : ndarray, shape (n_freqs,)
        Hz.
    gamma2 : ndarray, shape (n_freqs, n_outputs)
        ``γ²_{y:x}`` ∈ [0, 1] (dimensionless); NaN where undefined.
    inputs, outputs : tuple of str
        Channel names.
    settings : dict
        The Welch settings of the cross-spectral matrix.
    """

    frequencies: np.ndarray
    gamma2: np.ndarray
    inputs: tuple[str, ...] = ()
    outputs: tuple[str, ...] = ()
    settings: dict = field(default_factory=dict)

    _tuple_fields = ("frequencies", "gamma2")

    def __post_init__(self) -> None:
        object.__setattr__(self, "frequencies", read_only(self.frequencies, float))
        object.__setattr__(self, "gamma2", read_only(self.gamma2, float))
        object.__setattr__(self, "inputs", tuple(self.inputs))
        object.__setattr__(self, "outputs", tuple(self.outputs))

    def __repr__(self) -> str:
        return (f"MultipleCoherence({len(self.outputs)} outputs {names_summary(self.outputs)} on "
                f"{len(self.inputs)} inputs {names_summary(self.inputs)}, {axis_summary(self.frequencies)})")
