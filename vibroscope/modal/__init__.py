"""Modal identification: peak picking on FRFs, output-only FDD/EFDD and SSI-COV (stabilization
diagram), MAC and mode pairing.

Imports nothing of vibroscope's but :mod:`vibroscope.spectral` and :mod:`vibroscope.signals`.
"""

from vibroscope.modal._results import ModalModel, Mode, mpc, normalize_shapes
from vibroscope.modal.fdd import efdd_damping, fdd, singular_values
from vibroscope.modal.mac import ModeMatch, mac, mac_matrix, match_modes
from vibroscope.modal.peak_picking import fit_sdof, half_power_bandwidth, peak_picking
from vibroscope.modal.ssi import Stabilization, output_covariances, ssi_cov

__all__ = [
    "ModalModel", "Mode", "normalize_shapes", "mpc",
    "peak_picking", "half_power_bandwidth", "fit_sdof",
    "fdd", "singular_values", "efdd_damping",
    "mac", "mac_matrix", "match_modes", "ModeMatch",
    "ssi_cov", "Stabilization", "output_covariances",
]
