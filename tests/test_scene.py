"""The scene contact provider: global search + LCP batch for N bodies and flat walls."""
from types import SimpleNamespace

import numpy as np
import pytest

from nurbsdem.contact.scene import SceneContacts
from nurbsdem.shapes import box_walls, ellipsoid, sphere


def kinematics(x, R, shapes, body_shape, W):
    pos = np.array([x[i] - R[i] @ shapes[body_shape[i]].centroid for i in range(len(x))])
    return SimpleNamespace(x=np.asarray(x, float), R=np.asarray(R, float), pose_origin=pos,
                           wall_displacement=np.zeros((W, 3)))


def test_spheres_on_the_floor_and_against_each_other():
    r = 0.02
    shapes = [sphere(r)]
    walls = list(box_walls([0, 0, 0], [0.2, 0.2, 0.2]).values())
    x = np.array([[0.05, 0.05, r - 1e-4],           # 0.1 mm into the floor
                  [0.05 + 2 * r - 2e-4, 0.05, r - 1e-4],   # 0.2 mm into body 0, 0.1 mm into the floor
                  [0.15, 0.15, 0.10]])              # free
    R = np.repeat(np.eye(3)[None], 3, axis=0)
    scene = SceneContacts(shapes, np.zeros(3, np.int64), walls)
    cs = scene(kinematics(x, R, shapes, [0, 0, 0], len(walls)))
    got = {(int(a), int(b)): d for a, b, d in zip(cs.body_a, cs.body_b, cs.depth)}
    floor = 3                                        # global index of the first wall
    assert got == pytest.approx({(0, 1): 2e-4, (0, floor): 1e-4, (1, floor): 1e-4}, abs=1e-12)
    assert cs.active == len(got) and cs.failed == 0
    k = list(got).index((0, 1))
    np.testing.assert_allclose(cs.normal[k], [1, 0, 0], atol=1e-10)      # from A towards B
    assert cs.monitored >= cs.active
    # warm start: the same call again reproduces the result
    cs2 = scene(kinematics(x, R, shapes, [0, 0, 0], len(walls)))
    np.testing.assert_allclose(cs2.depth, cs.depth, atol=1e-15)


def test_separated_bodies_give_no_contacts_and_moving_walls_follow():
    shapes = [ellipsoid(0.03, 0.02, 0.01)]
    walls = list(box_walls([0, 0, 0], [0.3, 0.3, 0.3]).values())
    x = np.array([[0.1, 0.1, 0.1], [0.2, 0.2, 0.2]])
    R = np.repeat(np.eye(3)[None], 2, axis=0)
    scene = SceneContacts(shapes, np.zeros(2, np.int64), walls)
    kin = kinematics(x, R, shapes, [0, 0], len(walls))
    assert scene(kin).active == 0
    kin.wall_displacement[0] = [0, 0, 0.0905]       # lift the floor 0.5 mm into body 0
    cs = scene(kin)
    assert cs.active == 1 and cs.body_a[0] == 0 and cs.body_b[0] == 2
    assert cs.depth[0] == pytest.approx(5e-4, abs=1e-12)


def test_failed_warm_starts_are_retried_cold():
    """The compiled dispatch (nurbsdem.contact.listed) solves again, cold, exactly the rows
    whose warm start failed, and takes the retries that converged."""
    from nurbsdem.contact.lcp import F_SD, I_FAIL, I_VALID, NF, NI
    from nurbsdem.contact.listed import _retry_cold, _take_converged

    prev_i = np.zeros((4, NI), np.int64)
    prev_i[:3, I_VALID] = 1            # pairs 0-2 have a previous solution, pair 3 is new
    warm = prev_i[:, I_VALID] == 1
    rf = np.zeros((5, NF))             # the list's rows (row 0 not due), solved in place
    rf[1:, F_SD] = -1e-6 * np.arange(1, 5)
    ri = np.zeros((5, NI), np.int64)
    ri[[2, 3, 4], I_FAIL] = 1          # warm: 2 and 3 fail; 4 fails from its (cold) start
    idx = np.arange(1, 5)
    again = _retry_cold(ri, idx, warm)
    assert again.tolist() == [2, 3]    # pair 4 was cold already: not solved again
    cf = np.zeros((2, NF))
    cf[:, F_SD] = [-2.5e-6, -3.5e-6]
    ci = np.zeros((2, NI), np.int64)
    ci[1, I_FAIL] = 1                  # pair 3 fails cold as well
    _take_converged(rf, ri, again, cf, ci)
    assert ri[:, I_FAIL].tolist() == [0, 0, 0, 1, 1]     # 2 recovered by the cold retry
    assert rf[2, F_SD] == -2.5e-6 and rf[3, F_SD] == -3e-6


def test_neighbour_lists_and_certificates_do_not_change_the_results(tmp_path):
    """The lid deck (every body in contact, a moving wall) solved with the skin and the
    separation certificates (default) and with a full search and every LCP at every
    evaluation: the same monitors to round-off, with fewer LCPs."""
    import csv
    from pathlib import Path

    from nurbsdem.io.deck import parse_deck
    from nurbsdem.solver import Solver

    deck = Path(__file__).resolve().parents[1] / "inputs" / "regression" / "lid_press.inp"

    def run(name, **opts):
        out = tmp_path / name
        summary = Solver(parse_deck(deck), output=out, quiet=True, contact_options=opts).run()
        cols = {}
        for mon in ("energy.csv", "wall_lid.csv"):
            with open(out / "monitors" / mon) as fh:
                rows = list(csv.DictReader(fh))
            cols.update({f"{mon}:{k}": np.array([float(r[k]) for r in rows]) for k in rows[0]})
        return summary, cols

    fast, a = run("fast")
    full, b = run("full", skin=0.0, certificates=False)
    assert fast.lcps < 0.95 * full.lcps and fast.active_total == full.active_total
    for k in a:
        scale = max(np.abs(b[k]).max(), 1e-300)
        np.testing.assert_allclose(a[k], b[k], rtol=1e-9, atol=1e-12 * scale, err_msg=k)


def test_the_list_goes_stale_on_displacement_not_on_path():
    """A body that jiggles back to where the list was built leaves it valid (its path is
    long, its displacement nil); a turn by θ about the centroid moves a point at the bounding
    radius r by 2 r sin(θ/2), which makes the list stale once it exceeds half the skin; a
    wall's displacement counts alike."""
    from nurbsdem.contact.verlet import list_is_stale
    from nurbsdem.geometry.rotation import quat_from_rotvec, quat_to_matrix

    x = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    R = np.stack([np.eye(3), np.eye(3)])
    wall = np.zeros((1, 3))
    radius = np.array([0.02, 0.05])
    skin = 1e-3
    built = (x.copy(), R.copy(), wall.copy())
    for _ in range(10):                                   # 10 mm of path, back at the start
        assert not list_is_stale(*built, x + [[4e-4, 0, 0], [0, 0, 0]], R, wall, radius, skin)
    assert not list_is_stale(*built, x, R, wall, radius, skin)
    assert list_is_stale(*built, x + [[0, 6e-4, 0], [0, 0, 0]], R, wall, radius, skin)
    theta = 2 * np.arcsin(0.5 * skin / (2 * radius[1]))   # 2 r sin(θ/2) = s/2 exactly
    for f, stale in ((0.99, False), (1.01, True)):
        Rt = R.copy()
        Rt[1] = quat_to_matrix(quat_from_rotvec(np.array([0.0, 0.0, f * theta])))
        assert list_is_stale(*built, x, Rt, wall, radius, skin) == stale
    assert not list_is_stale(*built, x, R, wall + [[0, 0, 4.9e-4]], radius, skin)
    assert list_is_stale(*built, x, R, wall + [[0, 0, 6e-4]], radius, skin)
    assert list_is_stale(*built, x, R, wall, radius, 0.0)  # no skin: built at every call


class _RankOwning:
    """What a scene asks of its MPI domain (:class:`~nurbsdem.parallel.Domain`), for a rank
    that owns the particles ``owned`` (N,) bool and is the only rank."""

    def __init__(self, owned: np.ndarray) -> None:
        self.owned = owned
        self.lcps = self.failed = 0

    def any(self, flag: bool) -> bool:
        return bool(flag)

    def sync_for_build(self, kin):
        return kin

    def after_build(self, a, b) -> None:
        pass

    def counted(self, a) -> np.ndarray:
        return self.owned[np.asarray(a, np.int64)]

    def count_work(self, a, b, due) -> None:
        pass


@pytest.mark.parametrize("side", [3, 6])
@pytest.mark.parametrize("rank", [False, True], ids=["serial", "rank"])
def test_a_rebuild_renews_only_the_moved_bodies_and_equals_a_full_build(side, rank):
    """Each body keeps its own built pose: a rebuild renews the poses of the bodies (and
    walls) that moved more than REPOSE_FRACTION of half the skin and tests only their pairs'
    patch boxes (and, past ALL_PAIRS_MAX bodies, searches only their bounding spheres); the
    list equals a full build at the bodies' built poses, to the bit, and still holds every
    pair whose bounding spheres and patch boxes overlap at the present poses (with at least
    those candidate patches).  The same on an MPI rank that owns half of the particles: its
    list holds the pairs with an owned particle, as its full build would."""
    from scipy.spatial.transform import Rotation

    from nurbsdem.contact.boxes import candidate_patch_masks_batch_jit
    from nurbsdem.contact.broadphase import ALL_PAIRS_MAX
    from nurbsdem.contact.listed import PARTIAL_SEARCH_MAX, scene_list
    from nurbsdem.contact.verlet import REPOSE_FRACTION

    rng = np.random.default_rng(7)
    shapes = [ellipsoid(0.012, 0.009, 0.007), sphere(0.008)]
    g = np.stack(np.meshgrid(*[np.arange(side)] * 3, indexing="ij"), -1).reshape(-1, 3)
    n = g.shape[0]
    assert (n > ALL_PAIRS_MAX) == (side == 6)     # the bounding spheres of the renewed only
    body_shape = (np.arange(n) % 4 == 3).astype(np.int64)   # a sphere every fourth body
    x = 0.03 + 0.021 * g + rng.uniform(-1e-3, 1e-3, (n, 3))
    R = Rotation.random(n, random_state=3).as_matrix()
    top = 0.12 if side == 3 else 0.06 + 0.021 * side
    walls = list(box_walls([0, 0, 0], [top, top, top]).values())
    W = len(walls)
    skin = 2e-3
    scene = SceneContacts(shapes, body_shape, walls, skin=skin)
    owned = np.ones(n, np.bool_)
    if rank:
        owned = x[:, 0] < np.median(x[:, 0])
        scene.domain = _RankOwning(owned)
    kin = kinematics(x, R, shapes, body_shape, W)
    scene(kin)
    assert scene.builds == 1
    m = scene.margin + scene.skin
    for step in range(6):
        old = scene.built_pose
        move = np.zeros(n)
        some = rng.permutation(n)
        move[some[:3]] = rng.uniform(0.6, 1.5, 3) * skin          # past half the skin
        move[some[3:7]] = rng.uniform(0.0, 0.2, 4) * skin         # a little
        d = rng.normal(size=(n, 3))
        x = x + d / np.linalg.norm(d, axis=1, keepdims=True) * move[:, None]
        R = Rotation.from_rotvec(rng.normal(scale=0.02 * skin / 0.012, size=(n, 3))).as_matrix() @ R
        kin = kinematics(x, R, shapes, body_shape, W)
        kin.wall_displacement[-1] = [0, 0, -0.4 * skin * step]          # the lid comes down
        scene(kin)
        assert scene.builds == 2 + step
        bx, bR, bw, bp = scene.built_pose
        renewed = np.any(bx != old[0], axis=1)
        assert 3 <= renewed.sum() < n // 2                 # the moved bodies, not all
        assert side == 3 or renewed.sum() <= PARTIAL_SEARCH_MAX * n
        np.testing.assert_array_equal(bx[~renewed], old[0][~renewed])
        np.testing.assert_array_equal(bx[renewed], x[renewed])
        assert np.all(np.linalg.norm(x - bx, axis=1) <= REPOSE_FRACTION * skin / 2 + 0.03 * skin)
        full = scene_list(scene.tables(), bx, bp, bR, bw, owned, m,
                          np.zeros(0, np.int64), np.zeros((0, scene.P), np.bool_),
                          np.zeros((0, scene.P), np.bool_), np.ones(n + W, np.bool_))
        ps = scene.pairs
        for got, want in zip((ps.a, ps.b, ps.keys, ps.mask_a, ps.mask_b), full):
            np.testing.assert_array_equal(got, want)
        # a valid list at the present poses: every pair of overlapping bounding spheres
        # (level 1: a patch box can reach beyond its body's bounding sphere) and patch boxes
        # (level 2) is in it
        r = scene.radius
        nurbs = np.array([(i, j) for i in range(n) for j in range(i + 1, n)
                          if (body_shape[i] == 0 or body_shape[j] == 0)
                          and (owned[i] or owned[j])
                          and np.linalg.norm(x[i] - x[j]) < r[i] + r[j]])
        t = scene.tables()
        keep, ma, mb = candidate_patch_masks_batch_jit(t.boxes, t.box_offsets, t.body_shape,
                                                       kin.pose_origin, R, nurbs, 0.0, scene.P)
        listed = {int(k): r for r, k in enumerate(ps.keys)}
        assert keep.sum() > 10
        for (i, j), a_, b_ in zip(nurbs[keep], ma[keep], mb[keep]):
            r = listed[int(i * scene.nb + j)]
            assert np.all(ps.mask_a[r] >= a_) and np.all(ps.mask_b[r] >= b_)
    if rank:        # a re-cut: the rank's next build lists the newly owned particles' pairs
        owned = ~owned
        scene.domain = _RankOwning(owned)
        x = x + [[0.0, 0.0, skin]] * (np.arange(n)[:, None] == 0)
        scene(kinematics(x, R, shapes, body_shape, W))
        bx, bR, bw, bp = scene.built_pose
        full = scene_list(scene.tables(), bx, bp, bR, bw, owned, m, np.zeros(0, np.int64),
                          np.zeros((0, scene.P), np.bool_), np.zeros((0, scene.P), np.bool_),
                          np.ones(n + W, np.bool_))
        for got, want in zip((scene.pairs.a, scene.pairs.b, scene.pairs.keys), full):
            np.testing.assert_array_equal(got, want)


def test_every_contact_is_among_the_rows_just_solved(tmp_path, monkeypatch):
    """The compiled loop takes the active contacts from the rows it has just solved
    (verlet.active_rows) instead of reading every listed row: that needs every row in contact
    to be due at the next search, i.e. never certified apart. Checked at every return of the
    loop on the lid deck (a moving wall, certificates and rebuilds): the pairs not certified
    at the present reach hold exactly the active rows of the whole list."""
    from pathlib import Path

    from nurbsdem.contact.verlet import active_and_near, active_rows
    from nurbsdem.dynamics import deck_steps
    from nurbsdem.io.deck import parse_deck
    from nurbsdem.solver import Solver

    seen = {"returns": 0, "certified": 0, "active": 0}
    store = deck_steps.DeckSteps._store

    def checked_store(self, pl, ev, *args):
        due = np.flatnonzero(~(pl.budget > ev.reach))
        sel = active_and_near(pl.rows_f, pl.rows_i, pl.budget, ev.reach)[0]
        np.testing.assert_array_equal(active_rows(pl.rows_i, due), sel)
        seen["returns"] += 1
        seen["certified"] += pl.a.shape[0] - due.shape[0]
        seen["active"] += sel.shape[0]
        return store(self, pl, ev, *args)

    monkeypatch.setattr(deck_steps.DeckSteps, "_store", checked_store)
    deck = Path(__file__).resolve().parents[1] / "inputs" / "regression" / "lid_press.inp"
    Solver(parse_deck(deck), output=tmp_path / "out", quiet=True).run()
    assert seen["returns"] > 3 and seen["certified"] > 0 and seen["active"] > 0
