"""Models: lumped multi-DOF structures, nonlinear elements, excitations, time simulation
and model files.

``vibroscope.models`` imports nothing of vibroscope's but :mod:`vibroscope.signals`,
:mod:`vibroscope.errors` and the lazy-import helper :mod:`vibroscope._lazy` (simulation,
excitations and model files load on first use).
"""

from vibroscope._lazy import lazy_attributes
from vibroscope.models.controller import Controller
from vibroscope.models.elements import (
    Backlash,
    BoucWen,
    CubicSpring,
    Damper,
    Element,
    Friction,
    MRDamper,
    SignedDamper,
    SignedMass,
    SignedSpring,
    Spring,
    make_element,
)
from vibroscope.models.lumped import (Dof, Input, LumpedModel, Modes, Output, close_modes_model, demo_model,
                                      demo_model_5dof)
from vibroscope.models.modal_model import PoleResidueModel

__all__ = [
    "Dof",
    "Input",
    "Output",
    "Modes",
    "LumpedModel",
    "Controller",
    "PoleResidueModel",
    "demo_model",
    "demo_model_5dof",
    "close_modes_model",
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
    "make_element",
]


#: names loaded on first use (simulation, excitations, model files), by the module that defines them
_LAZY = {
    "simulate_periodic": "simulate", "reconstruct_input": "simulate", "default_oversample": "simulate",
    "upsample": "resample", "decimate_fir": "resample", "decimate_sharp": "resample",
    "boucwen_benchmark_model": "boucwen_benchmark", "simulate_boucwen_benchmark": "boucwen_benchmark",
    "band_limited_random": "excitation", "multisine": "excitation", "sine_sweep": "excitation",
    "impact": "excitation", "step": "excitation", "Excitation": "excitation", "parse_excitation": "excitation",
    "TransferFunctionModel": "modelfile", "load_model": "modelfile", "dump_model": "modelfile",
    "loads_model": "modelfile", "dumps_model": "modelfile",
}

# A submodule's name always means the submodule (submodules=True), as it does once anything has
# imported it (`from vibroscope.models.simulate import upsample` binds it here):
# `vibroscope.models.simulate` is the module, its function `vibroscope.models.simulate.simulate`
# (or `vibroscope.simulate`).
__getattr__, __dir__ = lazy_attributes(__name__, {k: f".{m}" for k, m in _LAZY.items()}, submodules=True)
