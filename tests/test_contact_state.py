"""The contacts of a system as one struct of arrays (nurbsdem.dynamics.contact_state): the
compiled loop's evaluation converts to it by name, a checkpoint stores it field by field
and gives it back, and an older checkpoint without the later fields keeps the system's."""
import numpy as np

from nurbsdem.dynamics.contact_state import (CHECKPOINT_KEYS, ContactState, checkpoint_arrays,
                                             contacts_of, from_checkpoint, no_contacts)
from nurbsdem.dynamics.loop_state import Evaluation


def _contacts(K: int, seed: int = 0) -> ContactState:
    rng = np.random.default_rng(seed)
    empty = no_contacts()
    return ContactState(**{f: (rng.integers(0, 9, (K, *v.shape[1:])).astype(v.dtype)
                               if v.dtype == np.int64 else rng.normal(size=(K, *v.shape[1:])))
                           for f, v in empty._asdict().items()})


def test_no_contacts_has_each_fields_row_shape():
    c = no_contacts()
    assert all(v.shape[0] == 0 for v in c)
    assert c.point.shape == (0, 3) and c.eel.shape == (0, 2) and c.coeffs.shape == (0, 4)
    assert c.fet.shape == (0, 6) and c.a.dtype == np.int64 and c.stick.dtype == np.int64


def test_the_loops_evaluation_converts_by_name():
    c = _contacts(5)
    ev = Evaluation(**{f: (getattr(c, f) if f in ContactState._fields else None)
                       for f in Evaluation._fields})
    back = contacts_of(ev)
    assert all(x is y for x, y in zip(back, c))
    flat = contacts_of(ev._replace(image=np.zeros((0, 3))))   # no periodic cell
    np.testing.assert_array_equal(flat.image, np.zeros((5, 3)))


def test_a_checkpoint_gives_the_contacts_back_and_an_older_one_keeps_the_later_fields():
    c = _contacts(4, 1)
    st = checkpoint_arrays(c)
    assert tuple(st) == CHECKPOINT_KEYS and st["c_key"] is not c.key
    back = from_checkpoint(st, no_contacts())
    for f in ContactState._fields:
        np.testing.assert_array_equal(getattr(back, f), getattr(c, f))
    older = {k: v for k, v in st.items() if k not in ("c_coeffs", "c_radius", "c_image")}
    previous = _contacts(4, 2)
    kept = from_checkpoint(older, previous)
    assert kept.coeffs is previous.coeffs and kept.image is previous.image
    np.testing.assert_array_equal(kept.a, c.a)
