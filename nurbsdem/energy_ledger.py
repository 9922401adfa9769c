"""The energies of a run over its solution steps (:class:`EnergyLedger`): each dynamic step's
system counts its dissipation and external work from zero, the ledger adds what the systems
before it left, so that ``monitors/energy.csv`` is cumulative over the whole run and its
balance error refers to the first row's mechanical energy."""
from __future__ import annotations

from .dynamics.energy import EnergySample


class EnergyLedger:
    """The offsets (J) of the systems closed so far (:attr:`offset`: dissipated, external
    work), the reference mechanical energy (J) of the first row (:attr:`mech0`, None before
    it) and the last row written (:attr:`last_row`)."""

    def __init__(self) -> None:
        self.offset = {"dissipated": 0.0, "external_work": 0.0}
        self.mech0: float | None = None
        self.last_row: dict = {}

    def row(self, e: EnergySample) -> dict:
        """The energies of a monitor row (J) of the running system's sample ``e``, the
        offsets added; the first row sets the reference."""
        diss = self.offset["dissipated"] + e.dissipated
        ext = self.offset["external_work"] + e.external_work
        mech = e.mechanical
        if self.mech0 is None:
            self.mech0 = mech
        row = dict(kinetic=e.kinetic, potential=e.potential, elastic=e.elastic,
                   dissipated=diss, external_work=ext, mechanical=mech,
                   balance_error=mech - self.mech0 - ext + diss)
        self.last_row = row
        return row

    def end_row(self, e: EnergySample, step: int, time: float) -> dict:
        """The energies (J, floats) of :meth:`row` at the end of step ``step``, time ``time``
        (s), without setting the reference or the last row."""
        diss = self.offset["dissipated"] + e.dissipated
        ext = self.offset["external_work"] + e.external_work
        mech0 = self.mech0 if self.mech0 is not None else e.mechanical
        return dict(step=step, time=float(time),
                    kinetic=float(e.kinetic), potential=float(e.potential),
                    elastic=float(e.elastic), dissipated=float(diss),
                    external_work=float(ext), mechanical=float(e.mechanical),
                    balance_error=float(e.mechanical - mech0 - ext + diss))

    def close(self, e: EnergySample) -> None:
        """Fold the cumulative energies ``e`` of a system that ends into the offsets."""
        self.offset["dissipated"] += e.dissipated
        self.offset["external_work"] += e.external_work

    def book_external(self, work: float) -> None:
        """Energy ``work`` (J) brought from outside the systems (copies of particles), booked
        once the ledger has its reference (before, it is part of the initial state, which
        the reference takes in: booking it too would count it twice)."""
        if self.mech0 is not None:
            self.offset["external_work"] += work

    def balance(self) -> tuple[float, float]:
        """(error, energy turned over) of the last row, J: its balance error, and its
        dissipated energy and external work in absolute value summed."""
        row = self.last_row
        return (row.get("balance_error", 0.0),
                max(abs(row.get("dissipated", 0.0)) + abs(row.get("external_work", 0.0)), 0.0))
