"""The per-row passes that run on threads in large scenes (``nurbsdem.jit.THREADED_ROWS``)
give every row the bits of the single-threaded pass, whatever the number of threads.

Each kernel is called on more rows than the threshold (its threaded branch) and compared, to
the bit, with the same kernel on slices shorter than the threshold (its one-thread branch) or
with the one-thread loop over the same row function, with numba's threads at 1 and at all.
"""
from __future__ import annotations

import numba
import numpy as np
import pytest
from numba import njit

from nurbsdem.contact.verlet import active_arrays
from nurbsdem.dynamics.forces import (N_TERMS, _add_contact_loads, _contact_laws_range,
                                      contact_forces, kick_work_terms)
from nurbsdem.dynamics.integrator import _relative_point_velocities, drift, half_kick
from nurbsdem.dynamics.rigid import body_poses, omega_world
from nurbsdem.contact.lcp import NF, NI
from nurbsdem.jit import THREADED_ROWS

N = THREADED_ROWS + 1234           # bodies: the threaded branch
W = 3                              # walls (bodies N .. N+W-1)
K = 2 * THREADED_ROWS + 77         # contacts
SLICE = THREADED_ROWS // 3         # slices below the threshold: the one-thread branch


def _same(a, b) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and a.tobytes() == b.tobytes()


@pytest.fixture(scope="module")
def scene():
    rng = np.random.default_rng(7)
    q = rng.normal(size=(N, 4))
    q /= np.linalg.norm(q, axis=1)[:, None]
    inv_I = 1.0 + rng.random((N, 3))
    inv_I[::5] = inv_I[::5, :1]             # some spheres: the isotropic rotation
    a = rng.integers(0, N + W, K)
    b = rng.integers(0, N, K)
    return dict(x=rng.normal(size=(N, 3)), v=rng.normal(size=(N, 3)), q=q,
                L=rng.normal(size=(N, 3)), inv_I=inv_I, inv_mass=1.0 + rng.random(N),
                force=rng.normal(size=(N, 3)), torque=rng.normal(size=(N, 3)),
                P=np.linalg.qr(rng.normal(size=(N, 3, 3)))[0], centroid=rng.normal(size=(N, 3)),
                a=a, b=b, point=rng.normal(size=(K, 3)), wall_d=rng.normal(size=(W, 3)),
                wall_u=rng.normal(size=(W, 3)), omega=rng.normal(size=(N, 3)), rng=rng)


@pytest.fixture(params=[1, "all"])
def threads(request):
    """numba's threads at 1 and at all (restored after)."""
    before = numba.get_num_threads()
    numba.set_num_threads(1 if request.param == 1 else numba.config.NUMBA_NUM_THREADS)
    yield
    numba.set_num_threads(before)


def _slices(n):
    return [slice(i, min(i + SLICE, n)) for i in range(0, n, SLICE)]


def test_body_passes_on_threads_have_the_bits_of_one_thread(scene, threads):
    s = scene
    v, L = s["v"].copy(), s["L"].copy()
    half_kick(v, L, s["force"], s["torque"], s["inv_mass"], 0.37)
    x, q = s["x"].copy(), s["q"].copy()
    drift(x, v, q, L, s["inv_I"], 1e-3)
    omega = omega_world(q, L, s["inv_I"])
    R, pos = body_poses(q, s["P"], x, s["centroid"])
    vs, Ls, xs, qs = s["v"].copy(), s["L"].copy(), s["x"].copy(), s["q"].copy()
    for sl in _slices(N):
        vv, LL, xx, qq = vs[sl], Ls[sl], xs[sl], qs[sl]    # views: updated in place
        half_kick(vv, LL, s["force"][sl], s["torque"][sl], s["inv_mass"][sl], 0.37)
        drift(xx, vv, qq, LL, s["inv_I"][sl], 1e-3)
        assert _same(omega_world(qq, LL, s["inv_I"][sl]), omega[sl])
        Rs, ps = body_poses(qq, s["P"][sl], xx, s["centroid"][sl])
        assert _same(Rs, R[sl]) and _same(ps, pos[sl])
    assert _same(vs, v) and _same(Ls, L) and _same(xs, x) and _same(qs, q)


def test_contact_passes_on_threads_have_the_bits_of_one_thread(scene, threads):
    s = scene
    out = np.empty((K, 3))
    _relative_point_velocities(s["a"], s["b"], s["point"], s["x"], s["wall_d"], s["v"],
                               s["omega"], s["wall_u"], out)
    f = [s["rng"].normal(size=(K, 3)) for _ in range(4)]
    terms = kick_work_terms(s["a"], s["b"], N, out, out[::-1].copy(), s["wall_u"], *f, 0.5)
    assert terms.shape == (K, N_TERMS)
    for sl in _slices(K):
        part = np.empty((sl.stop - sl.start, 3))
        _relative_point_velocities(s["a"][sl], s["b"][sl], s["point"][sl], s["x"], s["wall_d"],
                                   s["v"], s["omega"], s["wall_u"], part)
        assert _same(part, out[sl])
        t = kick_work_terms(s["a"][sl], s["b"][sl], N, out[sl], out[::-1][sl].copy(),
                            s["wall_u"], *[g[sl] for g in f], 0.5)
        assert _same(t, terms[sl])


@njit
def _forces_one_thread(a, b, pa, pb, nrm, dep, pos, vel, omg, material, table, spring, h,
                       inv_mass, radius, force, torque, point, ftot, fdn, fdt, fet, fn, eel,
                       stick, coeffs, given, dashpot):
    """contact_forces' one-thread branch, for any number of contacts."""
    slip = np.empty(a.shape[0])
    _contact_laws_range(a, b, pa, pb, nrm, dep, pos, vel, omg, material, table, spring, h,
                        inv_mass, radius, point, ftot, fdn, fdt, fet, fn, eel, stick, coeffs,
                        given, dashpot, slip, 0, a.shape[0])
    _add_contact_loads(a, b, pos, point, ftot, fet, force, torque)
    total = 0.0
    for c in range(a.shape[0]):
        total += slip[c]
    return total


@pytest.mark.parametrize("model", [0, 1])
def test_contact_laws_on_threads_have_the_bits_of_one_thread(scene, threads, model):
    """Linear (Eq. 16-17) and Hertz-Mindlin rows with rolling friction, sliding and sticking
    contacts: the laws on threads, the loads added in contact order."""
    from nurbsdem.dynamics.forces import ContactLaw, InterfaceTable
    from nurbsdem.dynamics.laws.hertz_mindlin import HertzMindlin as HertzMindlinLaw
    s, rng = scene, scene["rng"]
    B = N + W
    pos = np.concatenate((s["x"], s["wall_d"]))
    vel = np.concatenate((s["v"], s["wall_u"]))
    omg = np.concatenate((s["omega"], np.zeros((W, 3))))
    nrm = rng.normal(size=(K, 3))
    nrm /= np.linalg.norm(nrm, axis=1)[:, None]
    law = (ContactLaw(en=1e5, cn=50.0, et=1e4, ct=5.0, mu=0.3, mu_r=0.2) if model == 0 else
           HertzMindlinLaw(e_star=1e7, g_star=4e6, restitution=0.6, mu=0.3, mu_r=0.2))
    table = InterfaceTable(law).as_array(1)
    args = (s["a"], s["b"], rng.normal(size=(K, 3)), rng.normal(size=(K, 3)), nrm,
            1e-3 * rng.random(K), pos, vel, omg, np.zeros(B, np.int64), table)
    spring = 1e-3 * rng.normal(size=(K, 6))                 # tangential and rolling springs
    rest = (1e-4, np.concatenate((s["inv_mass"], np.zeros(W))), 0.01 + rng.random(K))
    outs = []
    for fn in (contact_forces, _forces_one_thread):
        o = [np.zeros((B, 3)), np.zeros((B, 3))] + [np.empty((K, 3)) for _ in range(4)] + [
            np.empty((K, 6)), np.empty(K), np.empty((K, 2)), np.empty(K, np.int64),
            np.empty((K, 4))]
        sp = spring.copy()
        slip = fn(*args, sp, *rest, *o, np.bool_(False), np.zeros(0))
        outs.append((slip, sp, o))
    (slip1, sp1, o1), (slip2, sp2, o2) = outs
    assert 0 < o1[9].sum() < K                       # some stick, some slide
    assert slip1 == slip2 and _same(sp1, sp2)
    assert all(_same(u, w) for u, w in zip(o1, o2))


def test_contact_arrays_on_threads_have_the_bits_of_one_thread(threads):
    rng = np.random.default_rng(3)
    M = 3 * THREADED_ROWS
    rows_f, rows_i = rng.normal(size=(M, NF)), rng.integers(0, 9, (M, NI))
    a, b, keys = rng.integers(0, 99, M), rng.integers(0, 99, M), np.arange(M) * 7
    sel = np.sort(rng.choice(M, THREADED_ROWS + 5, replace=False))
    whole = active_arrays(rows_f, rows_i, a, b, keys, sel, np.int64(0))
    parts = [active_arrays(rows_f, rows_i, a, b, keys, sel[sl], np.int64(0))
             for sl in _slices(sel.size)]
    for k, arr in enumerate(whole):
        assert _same(arr, np.concatenate([p[k] for p in parts]))


def test_implicit_dashpots_on_threads_have_the_bits_of_one_thread(scene, threads):
    """The dashpots' lever arms, normal rows and the velocities of their Delassus products
    on threads."""
    from nurbsdem.dynamics.implicit import (_velocities_range, delassus_apply, lever_arms,
                                            normal_rows)
    s, rng = scene, scene["rng"]
    r_a, r_b, rows = np.empty((K, 3)), np.empty((K, 3)), np.empty((K, 2, 6))
    lever_arms(s["a"], s["b"], s["point"], s["x"], r_a, r_b)
    nrm = rng.normal(size=(K, 3))
    nrm /= np.linalg.norm(nrm, axis=1)[:, None]
    Q = rng.normal(size=(N, 3, 3))
    sq_m, sq_I = 1.0 + rng.random(N), 1.0 + rng.random((N, 3))
    normal_rows(s["a"], s["b"], r_a, r_b, nrm, Q, sq_m, sq_I, rows)
    ra1, rb1, rows1 = np.empty((K, 3)), np.empty((K, 3)), np.empty((K, 2, 6))
    for sl in _slices(K):
        lever_arms(s["a"][sl], s["b"][sl], s["point"][sl], s["x"], ra1[sl], rb1[sl])
        normal_rows(s["a"][sl], s["b"][sl], ra1[sl], rb1[sl], nrm[sl], Q, sq_m, sq_I, rows1[sl])
    assert _same(ra1, r_a) and _same(rb1, r_b) and _same(rows1, rows)
    f = rng.normal(size=K)
    use = rng.random(K) < 0.9
    y, g = np.empty(6 * N), np.empty(K)
    delassus_apply(f, use, s["a"], s["b"], rows, y, g)
    g1 = np.empty(K)
    _velocities_range(s["a"], s["b"], rows, y, g1, 0, K)      # one thread, the same y
    assert _same(g, g1)


def test_search_passes_on_threads_select_what_a_scan_selects(threads):
    """The neighbour list's passes of each evaluation: the pairs' reach and the due rows
    (``due_rows``), the certificates' renewal, the active rows among the due ones and the
    bodies' displacements, threaded above the threshold, give a one-thread scan's arrays
    (chunks that keep none of their rows, all of them, or some)."""
    from nurbsdem.contact.lcp import F_SD, I_ACTIVE, I_FAIL, I_VALID
    from nurbsdem.contact.verlet import (active_rows, due_rows, largest_displacements,
                                         renew_certificates)
    from nurbsdem.jit import ROW_CHUNK
    rng = np.random.default_rng(11)
    M = 4 * THREADED_ROWS + 17
    a, b = rng.integers(0, N + W, M), rng.integers(0, N + W, M)
    odo = rng.random(N + W)
    budget = np.where(rng.random(M) < 0.5, -np.inf, 2.5 * rng.random(M))
    budget[:ROW_CHUNK] = np.inf                      # a chunk with no due row
    budget[ROW_CHUNK:2 * ROW_CHUNK] = -np.inf        # one with every row due
    reach_ref = odo[a] + odo[b]
    for cert in (True, False):
        reach, due = due_rows(a, b, odo, budget, cert)
        want = np.nonzero(~(budget > reach_ref))[0] if cert else np.arange(M)
        assert _same(reach, reach_ref) and _same(due, want)
    reach, due = due_rows(a, b, odo, budget, True)
    rows_f, rows_i = rng.normal(size=(M, NF)), rng.integers(0, 2, (M, NI))
    rows_i[:, I_FAIL] = rng.random(M) < 0.1
    rows_i[due[:ROW_CHUNK], I_ACTIVE] = 0                  # a chunk of due rows with none active
    keep = (rows_i[due, I_VALID] == 1) & (rows_i[due, I_ACTIVE] == 1)
    assert _same(active_rows(rows_i, due), due[keep])
    renewed = budget.copy()
    renew_certificates(renewed, due, rows_f, rows_i, reach)
    pieces = budget.copy()
    for sl in _slices(due.size):
        renew_certificates(pieces, due[sl], rows_f, rows_i, reach)
    assert _same(renewed, pieces)
    apart = ((rows_i[due, I_VALID] == 1) & (rows_i[due, I_ACTIVE] == 0)
             & (rows_i[due, I_FAIL] == 0) & (rows_f[due, F_SD] > 0))
    assert np.isfinite(renewed[due[apart]]).all() and np.isneginf(renewed[due[~apart]]).all()
    R = np.linalg.qr(rng.normal(size=(N, 3, 3)))[0]
    R0 = np.linalg.qr(rng.normal(size=(N, 3, 3)))[0]
    x, x0, rad = rng.normal(size=(N, 3)), rng.normal(size=(N, 3)), rng.random(N)
    wall, wall0 = rng.normal(size=(W, 3)), rng.normal(size=(W, 3))
    whole = largest_displacements(x, x0, R, R0, rad, wall, wall0)
    parts = [largest_displacements(x[sl], x0[sl], R[sl], R0[sl], rad[sl], wall[:0], wall0[:0])
             for sl in _slices(N)]
    assert _same(whole[:N], np.concatenate(parts))
    d = wall - wall0
    assert _same(whole[N:], np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2]))


def test_rows_carried_over_a_rebuild_on_threads_are_a_merges(threads):
    """``carry_rows`` (a rebuild of the list) on threads, each chunk's merge started by a
    binary search: every new key listed before takes its old row, certificate and flag, the
    others zeros, −inf and False (chunks with all, none or some of their keys listed)."""
    from nurbsdem.contact.verlet import carry_rows
    from nurbsdem.jit import ROW_CHUNK
    rng = np.random.default_rng(5)
    M = 3 * THREADED_ROWS
    old_keys = np.unique(rng.integers(0, 10 * M, M))
    M = old_keys.size
    old_f, old_i = rng.normal(size=(M, NF)), rng.integers(0, 9, (M, NI))
    old_budget, old_reused = rng.normal(size=M), rng.random(M) < 0.5
    fresh = np.setdiff1d(np.arange(10 * M), old_keys)
    keys = np.unique(np.concatenate((old_keys[ROW_CHUNK:3 * ROW_CHUNK],      # all listed
                                     fresh[:ROW_CHUNK],                      # none listed
                                     rng.choice(old_keys, THREADED_ROWS),    # some
                                     rng.choice(fresh, THREADED_ROWS))))
    rows_f, rows_i, budget, reused = carry_rows(old_keys, old_f, old_i, old_budget, old_reused,
                                                keys)
    idx = np.minimum(np.searchsorted(old_keys, keys), M - 1)
    listed = old_keys[idx] == keys
    assert 0 < listed.sum() < keys.size and keys.size > THREADED_ROWS
    assert _same(rows_f, np.where(listed[:, None], old_f[idx], 0.0))
    assert _same(rows_i, np.where(listed[:, None], old_i[idx], 0))
    assert _same(budget, np.where(listed, old_budget[idx], -np.inf))
    assert _same(reused, listed & old_reused[idx])
