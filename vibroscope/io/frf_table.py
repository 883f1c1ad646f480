"""The intermediate FRF table that each FRF file reader returns (:mod:`vibroscope.io.frf_csv`,
:mod:`vibroscope.io.uff58`), before :func:`vibroscope.io.frf_files.read_frf` applies names and
kind overrides and concatenates files; and the SI units of each FRF kind.

References
----------
.. [1] D. J. Ewins, *Modal Testing: Theory, Practice and Application*, 2nd ed., Research Studies
   Press, 2000, §1.3 (accelerance, mobility, receptance).
"""

from __future__ import annotations

from vibroscope.spectral.kinds import FRF_KIND_TABLE

#: FRF kind -> SI units of the response per unit force (read from the FRF-kind table)
KIND_UNITS = {k.name: k.unit for k in FRF_KIND_TABLE.values()}


class FrfTable:
    """One file's FRFs before names, kind overrides and concatenation: `frequencies` (n_freqs,) Hz, `H`
    complex (n_freqs, n_outputs, n_inputs), `coh` (n_freqs, n_outputs), the input and output
    names (`named`: the file named its outputs), `kind` or None, `units`, the format name and
    extra settings."""

    def __init__(self, *, path, frequencies, H, coh, inputs, outputs, named, kind, units, fmt, extra=None):
        self.path, self.frequencies, self.H, self.coh = path, frequencies, H, coh
        self.inputs, self.outputs, self.named = list(inputs), list(outputs), named
        self.kind, self.units, self.fmt, self.extra = kind, units, fmt, dict(extra or {})
