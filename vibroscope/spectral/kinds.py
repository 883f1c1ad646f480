"""The FRF kinds -- accelerance, mobility, receptance -- declared once.

Each kind is the response quantity per unit force (Ewins, *Modal Testing: Theory, Practice and
Application*, 2nd ed., Research Studies Press, 2000, §1.3): a receptance is displacement / force,
a mobility is ``jω`` times a receptance, an accelerance ``(jω)²`` times it. Every module that
converts, names, reads or writes an FRF kind reads :data:`FRF_KIND_TABLE` (the FRF result's
``to``, the estimators' unit inference, LSFD's residue powers, the UFF 58 reader and writer, the
``modal`` command's ``--kind``).
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["FRFKind", "FRF_KIND_TABLE", "FRF_KINDS", "power_of_jw", "kind_of_response_unit"]


@dataclass(frozen=True, kw_only=True)
class FRFKind:
    """One FRF kind.

    Attributes
    ----------
    name : str
        ``'accelerance'``, ``'mobility'`` or ``'receptance'``.
    quantity : str
        The response quantity: ``'acceleration'``, ``'velocity'``, ``'displacement'``.
    power : int
        Power ``p`` of ``jω`` that turns a receptance into this kind: ``H = (jω)^p · receptance``
        (0 receptance, 1 mobility, 2 accelerance).
    response_unit : str
        SI unit of the response: ``'m/s^2'``, ``'m/s'``, ``'m'``.
    unit : str
        SI unit of the FRF (response per newton): ``'m/s^2/N'``, ``'m/s/N'``, ``'m/N'``.
    uff_data_type : int
        The response's specific data type in a UFF 58 record (12 acceleration, 11 velocity,
        8 displacement; the force is 13).
    """

    name: str
    quantity: str
    power: int
    response_unit: str
    unit: str
    uff_data_type: int


#: the FRF kinds by name, in the order of :data:`FRF_KINDS`
FRF_KIND_TABLE: dict[str, FRFKind] = {k.name: k for k in (
    FRFKind(name="accelerance", quantity="acceleration", power=2, response_unit="m/s^2", unit="m/s^2/N",
            uff_data_type=12),
    FRFKind(name="mobility", quantity="velocity", power=1, response_unit="m/s", unit="m/s/N", uff_data_type=11),
    FRFKind(name="receptance", quantity="displacement", power=0, response_unit="m", unit="m/N", uff_data_type=8),
)}

#: FRF kinds by response quantity per unit force (Ewins, *Modal Testing*, 2000, §1.3)
FRF_KINDS = tuple(FRF_KIND_TABLE)


def power_of_jw(kind: str | None) -> int:
    """Power of ``jω`` that turns a receptance into an FRF of `kind` (an unknown kind: 0).

    Parameters
    ----------
    kind : {'accelerance', 'mobility', 'receptance'} or None
        The FRF kind; None (unknown) is treated as a receptance.

    Returns
    -------
    int
        2, 1 or 0.

    Raises
    ------
    KeyError
        If `kind` is neither None nor one of :data:`FRF_KINDS`.

    Examples
    --------
    >>> power_of_jw("accelerance"), power_of_jw(None)
    (2, 0)
    """
    return 0 if kind is None else FRF_KIND_TABLE[kind].power


def kind_of_response_unit(unit: str) -> str | None:
    """The FRF kind of a response in `unit` per newton (None when `unit` is none of the kinds').

    Parameters
    ----------
    unit : str
        The response's unit: ``'m/s^2'``, ``'m/s'`` or ``'m'``.

    Returns
    -------
    str or None
        ``'accelerance'``, ``'mobility'``, ``'receptance'``, or None.

    Examples
    --------
    >>> kind_of_response_unit("m/s")
    'mobility'
    """
    return next((k.name for k in FRF_KIND_TABLE.values() if k.response_unit == unit), None)
