"""Modal identification.

- EMA from FRFs: LSCF / polyMAX (:func:`lscf`, stabilization diagram) and LSFD residues and mode
  shapes (:func:`lsfd`); peak picking as the quick method.
- OMA: covariance-driven SSI (:func:`ssi_cov`), FDD / EFDD (:func:`fdd`).
- Physical-mode selection (:mod:`~vibroscope.modal.selection`), automatic identification with no
  hand-set band (:mod:`~vibroscope.modal.automatic`), block-bootstrap uncertainty
  (:mod:`~vibroscope.modal.uncertainty`), quality indicators (MAC, MPC, MPD, COMAC).

Imports nothing of vibroscope's but :mod:`vibroscope.spectral` and :mod:`vibroscope.signals`.
"""

from vibroscope.modal._results import ModalModel, Mode, mpc, normalize_shapes, ods_as_modal_model, with_operating_shapes
from vibroscope.modal.automatic import Identification, auto_lscf, auto_ssi, modes_document
from vibroscope.modal.compare import ModeSetComparison, compare_mode_sets
from vibroscope.modal.fdd import SingularValues, efdd_damping, fdd, singular_values
from vibroscope.modal.lscf import lscf
from vibroscope.modal.lsfd import LSFDResult, lsfd
from vibroscope.modal.mac import ModeMatch, mac, mac_matrix, match_modes
from vibroscope.modal.peak_picking import fit_sdof, half_power_bandwidth, peak_picking
from vibroscope.modal.quality import QualityTable, automac, comac, complexity, modal_quality, mpd
from vibroscope.modal.selection import RejectedMode, Selection, cluster_poles, pick_poles, select_modes
from vibroscope.modal.ssi import Stabilization, output_covariances, ssi_cov
from vibroscope.modal.uncertainty import ModalUncertainty, ssi_bootstrap

__all__ = [
    "ModalModel", "Mode", "normalize_shapes", "mpc", "ods_as_modal_model", "with_operating_shapes",
    "lscf", "lsfd", "LSFDResult",
    "peak_picking", "half_power_bandwidth", "fit_sdof",
    "fdd", "singular_values", "SingularValues", "efdd_damping",
    "mac", "mac_matrix", "match_modes", "ModeMatch", "compare_mode_sets", "ModeSetComparison",
    "automac", "comac", "complexity", "mpd", "modal_quality", "QualityTable",
    "ssi_cov", "Stabilization", "output_covariances",
    "select_modes", "cluster_poles", "pick_poles", "Selection", "RejectedMode",
    "auto_ssi", "auto_lscf", "Identification", "modes_document",
    "ssi_bootstrap", "ModalUncertainty",
]
