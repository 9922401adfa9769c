"""The contacts of a system's last force evaluation: one struct of arrays.

:class:`ContactState` holds one row per active contact, one name per quantity, in the names
the compiled deck steps' evaluation uses (:data:`~nurbsdem.dynamics.loop_state.Evaluation`
has the same fields, and more of the search's).  Both drivers of the internal step store it
(:class:`~nurbsdem.dynamics.system.DemSystem` ``.contacts``); the guards' energies, the
time-step control's network, the writers' contact output, the checkpoint and the MPI ranks'
deck-end merge read it.  Units: SI, world frame; K contacts.

* ``a``, ``b`` (K,) int64: the bodies (particles 0..N-1, walls N..N+W-1), ``key`` (K,) int64
  the pair's key (ascending within a rank's list order).
* ``point`` (K,3) m: where the contact force acts; ``normal`` (K,3): the unit normal
  (from A toward B).
* ``ftot`` (K,3) N: the force on B; ``fdn``, ``fdt`` (K,3) N: its normal and tangential
  dissipative parts; ``fet`` (K,6) N: its tangential elastic (spring) part in columns 0-2,
  the rolling spring's torque on B (N m) in columns 3-5 (paper Eq. 16-17 for the linear law);
  ``fn`` (K,) N: the normal force.
* ``eel`` (K,2) J: the normal and tangential elastic energies; ``stick`` (K,) int64: 1 stick,
  0 slip.
* ``coeffs`` (K,4): the tangent stiffnesses (N/m) and dampings (N s/m) (k_n, c_n, k_t, c_t)
  the time-step control takes; ``radius`` (K,) m: the equivalent contact radius (Hertz,
  rolling; zeros for linear laws); ``image`` (K,3) m: the translation of the image of B a
  contact touches in a periodic cell (zeros otherwise).

A checkpoint stores each field under ``c_<field>`` (:func:`checkpoint_arrays`,
:func:`from_checkpoint`).
"""
from __future__ import annotations

from collections import namedtuple
from typing import Mapping

import numpy as np

from .rolling import NSPRING

ContactState = namedtuple("ContactState", "a b key point normal ftot fdn fdt fet fn eel "
                                          "stick coeffs radius image")

#: the fields' trailing shapes and dtypes (K rows each)
_LAYOUT = dict(a=((), np.int64), b=((), np.int64), key=((), np.int64), point=((3,), float),
               normal=((3,), float), ftot=((3,), float), fdn=((3,), float),
               fdt=((3,), float), fet=((NSPRING,), float), fn=((), float), eel=((2,), float),
               stick=((), np.int64), coeffs=((4,), float), radius=((), float),
               image=((3,), float))
#: the checkpoint's name of a field
PREFIX = "c_"
CHECKPOINT_KEYS = tuple(PREFIX + f for f in ContactState._fields)


def no_contacts() -> ContactState:
    """No contacts (before the first evaluation)."""
    return ContactState(**{f: np.zeros((0, *shape), dtype) for f, (shape, dtype)
                           in _LAYOUT.items()})


def contacts_of(ev) -> ContactState:
    """The ContactState of the compiled loop's evaluation ``ev`` (the same names; a
    non-periodic evaluation's empty ``image`` becomes K rows of zeros)."""
    c = ContactState(**{f: getattr(ev, f) for f in ContactState._fields})
    K = c.a.shape[0]
    if c.image.shape[0] != K:
        c = c._replace(image=np.zeros((K, 3)))
    return c


def checkpoint_arrays(c: ContactState) -> dict[str, np.ndarray]:
    """The fields as a checkpoint stores them (copies, ``c_<field>``)."""
    return {PREFIX + f: np.array(v, copy=True) for f, v in zip(ContactState._fields, c)}


def from_checkpoint(st: Mapping[str, np.ndarray], previous: ContactState) -> ContactState:
    """The ContactState of a checkpoint's arrays; a field that a checkpoint of an earlier
    version lacks (``coeffs``, ``radius``, ``image``) keeps ``previous``'s (the compiled loop
    recomputes ``coeffs`` from the interface table where its rows do not match the
    contacts')."""
    return ContactState(**{f: np.array(st[PREFIX + f], copy=True) if PREFIX + f in st
                           else getattr(previous, f) for f in ContactState._fields})
