"""Models: lumped multi-DOF structures, nonlinear elements, excitations, time simulation
and model files.

``vibroscope.models`` imports nothing of vibroscope's but :mod:`vibroscope.signals` and
:mod:`vibroscope.errors`.
"""

from vibroscope.models.controller import Controller
from vibroscope.models.elements import (
    Backlash,
    BoucWen,
    CubicSpring,
    Damper,
    Element,
    Friction,
    MRDamper,
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
    "Damper",
    "CubicSpring",
    "Backlash",
    "Friction",
    "BoucWen",
    "MRDamper",
    "make_element",
]


def __getattr__(name):  # lazy: simulate / excitation / modelfile load on first use
    import importlib
    import importlib.util

    # A submodule's name always means the submodule, as it does once anything has imported it
    # (`from vibroscope.models.simulate import upsample` binds it here): `vibroscope.models.simulate`
    # is the module, its function `vibroscope.models.simulate.simulate` (or `vibroscope.simulate`).
    if importlib.util.find_spec(f"{__name__}.{name}") is not None:
        return importlib.import_module(f"{__name__}.{name}")
    for mod in ("simulate", "excitation", "modelfile"):
        m = importlib.import_module(f"vibroscope.models.{mod}")
        if name in getattr(m, "__all__", ()):
            return getattr(m, name)
    raise AttributeError(f"module 'vibroscope.models' has no attribute {name!r}")
