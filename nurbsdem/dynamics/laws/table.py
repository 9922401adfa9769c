"""The interface table: one contact law per pair of material indices, as the compiled force
kernels read it (a dense float array ``(M, M, NCOL)``, one row per pair).

Every law fills the same row layout:

* ``EN, CN, ET, CT``: a linearisation (k_n N/m, c_n N s/m, k_t N/m, c_t N s/m) of the law.  The
  a-priori time-step estimate and the time-step control's network read these columns for the
  pairs not in contact (:func:`~nurbsdem.dynamics.stepcontrol.contact_network`); for the linear
  penalty law they are its constants;
* ``MU``: the Coulomb coefficient (-) of the return mapping, common to all laws;
* ``MODEL``: the law's code (:data:`nurbsdem.dynamics.laws.LAWS_BY_CODE`), on which the kernels
  dispatch;
* ``P0 .. P2``: the law's own parameters (their meaning is the law's: Hertz–Mindlin keeps
  E*, G*, ζ there);
* ``RF``: the rolling-friction coefficient μ_r (-) of the rolling resistance common to all
  laws (:mod:`nurbsdem.dynamics.rolling`; 0: none);
* ``RD``: the rolling spring's damping ratio η_r (-) (0: none).

A row of NaN marks a pair without an interface (an input error when such a contact occurs).
"""
from __future__ import annotations

import numpy as np

from ...errors import InputError

#: column indices of the interface table
EN, CN, ET, CT, MU, MODEL = 0, 1, 2, 3, 4, 5
#: the law's own parameters
P0, P1, P2 = 6, 7, 8
#: the rolling-friction coefficient μ_r (-)
RF = 9
#: the rolling spring's damping ratio η_r (-)
RD = 10
#: number of columns
NCOL = 11


class InterfaceTable:
    """Contact laws per pair of material ids (symmetric), a small dense table ``(M, M, NCOL)``.

    A law is any registered law object (:mod:`nurbsdem.dynamics.laws`: it has ``as_row()``).

    ``table.set(0, 1, law)`` sets the interface between materials 0 and 1 (both orders);
    ``table.default`` is used for pairs never set (None: such a pair is an input error).
    """

    def __init__(self, default=None) -> None:
        self.default = default
        self.laws: dict[tuple[int, int], object] = {}

    def set(self, mat_a: int, mat_b: int, law) -> None:
        self.laws[(min(mat_a, mat_b), max(mat_a, mat_b))] = law

    def get(self, mat_a: int, mat_b: int):
        key = (min(mat_a, mat_b), max(mat_a, mat_b))
        if key in self.laws:
            return self.laws[key]
        if self.default is None:
            raise InputError(f"no contact interface defined between materials {mat_a} and {mat_b}")
        return self.default

    def as_array(self, n_materials: int) -> np.ndarray:
        """Dense (M, M, NCOL) float table; rows for undefined pairs are NaN (and raise on use)."""
        tab = np.full((n_materials, n_materials, NCOL), np.nan)
        for i in range(n_materials):
            for j in range(n_materials):
                key = (min(i, j), max(i, j))
                law = self.laws.get(key, self.default)
                if law is not None:
                    tab[i, j] = law.as_row()
        return tab


def codes_of(table: np.ndarray) -> set[int]:
    """The law codes a dense interface table (M, M, NCOL) uses (NaN rows aside)."""
    col = np.asarray(table)[..., MODEL]
    return {int(c) for c in np.unique(col[np.isfinite(col)])}
