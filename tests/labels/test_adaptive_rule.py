"""The adaptive rule (siteline.labels.change, LabelParams(rule="adaptive")): two scans that sample a
surface differently do not disagree about it, a place the other scan did not observe is not change,
leaves that moved are not change, and what really changed still is."""

from __future__ import annotations

import numpy as np

from siteline.labels.change import CHANGED, IGNORED, NOT_OBSERVED, UNCHANGED, Matching, change_flags
from siteline.records.params.labels import LabelParams
from siteline.site.taxonomy import default_taxonomy

TAX = default_taxonomy()
IGN = TAX.ignored_lut()
GROUND, BUILDING, VEG, TEMP = (TAX.id_of(n) for n in ("ground", "building", "vegetation", "temporary_works"))
R = 0.15  # the change radius: 2.5 x the spacing of ground at 80 points/m2


def _flags(
    a: np.ndarray, ac: np.ndarray, b: np.ndarray, bc: np.ndarray, rule: str = "adaptive"
) -> np.ndarray:
    test = LabelParams(rule=rule, surface_probe=0.7).surface_test(R)
    return change_flags(a, ac, b, bc, R, IGN, Matching(surface=test, ground=TAX.ground_lut()))


def _ground(
    rng: np.random.Generator, density: float, x=(0.0, 20.0), y=(0.0, 20.0), z=0.0, noise=0.02
) -> np.ndarray:
    n = int(density * (x[1] - x[0]) * (y[1] - y[0]))
    return np.c_[rng.uniform(*x, n), rng.uniform(*y, n), z + rng.normal(0, noise, n)]


def _wall(rng: np.random.Generator, density: float, x0=8.0, length=6.0, y=10.0, height=6.0) -> np.ndarray:
    """A wall in the plane y = ``y``, sampled at ``density`` points/m2 (a flight that grazed it)."""
    n = int(density * length * height)
    return np.c_[rng.uniform(x0, x0 + length, n), y + rng.normal(0, 0.02, n), rng.uniform(0, height, n)]


def _full(n: int, c: int) -> np.ndarray:
    return np.full(n, c, np.uint8)


def test_a_wall_both_scans_grazed_is_not_change_where_the_surface_rule_calls_it_so() -> None:
    rng = np.random.default_rng(1)
    # a wall sampled at 3 points/m2 by each flight (its own points each time), ground at 80 around it
    ga, gb = _ground(rng, 80.0), _ground(rng, 80.0)
    wa, wb = _wall(rng, 3.0), _wall(rng, 3.0)
    roof = lambda: np.c_[rng.uniform(8, 14, 400), rng.uniform(10, 10.3, 400), np.full(400, 6.0)]  # noqa: E731
    a, b = np.concatenate([ga, wa, roof()]), np.concatenate([gb, wb, roof()])
    ac = np.r_[_full(len(ga), GROUND), _full(len(wa) + 400, BUILDING)]
    bc = np.r_[_full(len(gb), GROUND), _full(len(wb) + 400, BUILDING)]
    wall = slice(len(ga), len(ga) + len(wa))
    old = _flags(a, ac, b, bc, "surface")[wall]
    new = _flags(a, ac, b, bc)[wall]
    z = a[wall][:, 2]
    assert (old == CHANGED).mean() > 0.2  # the surface rule: sparse points are not its surface
    # within reach of the dense ground at its foot and the dense roof strip over it, most of the
    # other scan's neighbours lie on those, as they do at the wall's ends: the point is then not
    # observed, or changed within the level of detection's reach of the ground (no scan tells that
    # from a low thing taken away)
    assert (new[(z > 0.8) & (z < 4.5)] == UNCHANGED).mean() > 0.95
    assert (new[z > 0.3] == CHANGED).sum() == 0 and (new == NOT_OBSERVED).mean() < 0.3


def test_a_wall_the_other_scan_did_not_observe_is_not_change_and_a_removed_one_is() -> None:
    rng = np.random.default_rng(2)
    ga, gb = _ground(rng, 80.0), _ground(rng, 80.0)
    wa = _wall(rng, 20.0)
    roof_a = np.c_[rng.uniform(8, 14, 600), rng.uniform(10, 12, 600), np.full(600, 6.0)]
    roof_b = np.c_[rng.uniform(8, 14, 600), rng.uniform(10, 12, 600), np.full(600, 6.0)]
    a = np.concatenate([ga, wa, roof_a])
    ac = np.r_[_full(len(ga), GROUND), _full(len(wa) + 600, BUILDING)]
    wall = slice(len(ga), len(ga) + len(wa))
    # B flew lines along the wall and never saw it, but saw the roof over it
    b = np.concatenate([gb, roof_b])
    bc = np.r_[_full(len(gb), GROUND), _full(600, BUILDING)]
    unseen = _flags(a, ac, b, bc)[wall]
    high = a[wall][:, 2] > 0.5
    assert (unseen[high] == NOT_OBSERVED).mean() > 0.9 and (unseen[high] == CHANGED).mean() < 0.02
    # a free-standing wall taken away: B saw open air where it stood
    gone = _flags(np.concatenate([ga, wa]), ac[: len(ga) + len(wa)], gb, _full(len(gb), GROUND))[wall]
    assert (gone[high] == CHANGED).mean() > 0.95


def test_a_fence_both_scans_saw_edge_on_is_not_change_and_one_taken_away_is() -> None:
    rng = np.random.default_rng(5)
    ga, gb = (_ground(rng, 80.0, x=(0.0, 62.0)) for _ in range(2))
    # a free-standing fence 3 m high along both flights' lines: seen edge-on, 0.8 returns a m2 of it
    # in each scan, not the same ones (the synthetic site's east and west fences at 1000 points/m2
    # hold 1/50 of the north fence's returns): a few of the other scan's lie within reach of each
    fence = lambda: _wall(rng, 0.8, x0=1.0, length=60.0, height=3.0)  # noqa: E731
    fa, fb = fence(), fence()
    a, b = np.concatenate([ga, fa]), np.concatenate([gb, fb])
    ac = np.r_[_full(len(ga), GROUND), _full(len(fa), TEMP)]
    bc = np.r_[_full(len(gb), GROUND), _full(len(fb), TEMP)]
    reach = LabelParams().surface_test(R).fit_m
    up = a[len(ga) :, 2] > reach  # beyond the ground's reach (nearer, its plane decides)
    flags = _flags(a, ac, b, bc)[len(ga) :][up]
    # those the other scan returned from beside, too thinly to fit a plane, are not observed (the
    # rule before called half of them changed)
    assert (flags == NOT_OBSERVED).mean() > 0.5 and (flags == CHANGED).mean() < 0.05
    # returns of another class beside it (a wall near a panel put up) do not say it was grazed
    bw = np.r_[_full(len(gb), GROUND), _full(len(fb), BUILDING)]
    assert (_flags(a, ac, b, bw)[len(ga) :][up] == CHANGED).mean() > 0.3
    # taken away: the other scan holds only the ground below it
    gone = _flags(a, ac, gb, _full(len(gb), GROUND))[len(ga) :]
    assert (gone[a[len(ga) :, 2] > 0.5] == CHANGED).mean() > 0.95


def test_formwork_moved_up_over_its_old_place_is_change() -> None:
    rng = np.random.default_rng(8)
    # formwork 1.2 m high, sampled thinly as an edge-on wall is, moved up on its plane (a floor
    # poured under it) leaving a gap of 0.6 of the rule's reach (the synthetic site's at 10 points/m2:
    # 2.3 m under a 3.7 m reach): the first scan's returns of it lie under the new ones, within reach
    old = _wall(rng, 2.0, x0=1.0, length=18.0, height=1.2) + [0.0, 0.0, 2.0]
    reach = LabelParams().surface_test(R).fit_m
    new = _wall(rng, 2.0, x0=1.0, length=18.0, height=1.2) + [0.0, 0.0, 3.2 + 0.6 * reach]
    ga, gb = _ground(rng, 80.0), _ground(rng, 80.0)
    a, b = np.concatenate([ga, old]), np.concatenate([gb, new])
    ac = np.r_[_full(len(ga), GROUND), _full(len(old), TEMP)]
    bc = np.r_[_full(len(gb), GROUND), _full(len(new), TEMP)]
    assert (_flags(b, bc, a, ac)[len(gb) :] == CHANGED).mean() > 0.95


def test_a_trench_narrower_than_the_reach_is_found() -> None:
    rng = np.random.default_rng(3)
    a = _ground(rng, 80.0)
    b = _ground(rng, 80.0)
    inside = (b[:, 0] > 9.4) & (b[:, 0] < 10.6)  # a 1.2 m trench dug 1.5 m deep along y
    b[inside, 2] -= 1.5
    fa = _flags(a, _full(len(a), GROUND), b, _full(len(b), GROUND))
    middle = (a[:, 0] > 9.7) & (a[:, 0] < 10.3)
    assert (fa[middle] == CHANGED).mean() > 0.95
    assert (fa[(a[:, 0] < 8.5) | (a[:, 0] > 11.5)] == CHANGED).mean() < 0.001
    # from the trench's side: its floor lies under the first scan's ground, which was there and is
    # gone (not a place that scan could not see)
    fb = _flags(b, _full(len(b), GROUND), a, _full(len(a), GROUND))
    assert (fb[inside & (b[:, 0] > 9.7) & (b[:, 0] < 10.3)] == CHANGED).mean() > 0.95
    # without ground classes (the geometry rule) the floor is taken as hidden from the first scan
    test = LabelParams(surface_probe=0.7).surface_test(R)
    blind = change_flags(b, _full(len(b), GROUND), a, _full(len(a), GROUND), R, IGN, Matching(surface=test))
    assert (blind[inside & (b[:, 0] > 9.7) & (b[:, 0] < 10.3)] == UNCHANGED).mean() > 0.95


def test_ground_under_a_beam_the_other_scan_had_is_hidden_not_changed() -> None:
    rng = np.random.default_rng(7)
    under = np.c_[rng.uniform(5, 6, 200), rng.uniform(5, 6, 200), np.zeros(200)]
    beam = np.c_[rng.uniform(4, 7, 2000), rng.uniform(4, 7, 2000), np.full(2000, 10.0)]
    fb = _flags(under, _full(200, GROUND), beam, _full(2000, TAX.id_of("crane")))
    assert (fb == UNCHANGED).all()


def test_a_beam_that_turned_is_found_where_its_new_place_crosses_its_old_plane() -> None:
    # the top of a 1 m beam at 18 m, turned 60 degrees about its end: near the end the two lie side by
    # side in one plane, and a point of the old beam is on the new beam's plane but beyond its edge
    rng = np.random.default_rng(4)

    def beam(angle: float) -> np.ndarray:
        s, w = rng.uniform(0, 12, 5000), rng.uniform(-0.5, 0.5, 5000)
        c, d = np.cos(angle), np.sin(angle)
        return np.c_[s * c - w * d, s * d + w * c, np.full(5000, 18.0) + rng.normal(0, 0.02, 5000)]

    ga, gb = _ground(rng, 40.0, (-15, 15), (-15, 15)), _ground(rng, 40.0, (-15, 15), (-15, 15))
    a, b = np.concatenate([ga, beam(0.0)]), np.concatenate([gb, beam(np.pi / 3)])
    c = np.r_[_full(len(ga), GROUND), _full(5000, TAX.id_of("crane"))]
    fa = _flags(a, c, b, c)[len(ga) :]
    old = a[len(ga) :]
    off = old[:, 0] > 2.5  # past where the two beams overlap
    assert (fa[off] == CHANGED).mean() > 0.97


def test_leaves_that_moved_are_not_change_and_a_tree_cut_down_is() -> None:
    rng = np.random.default_rng(5)

    def crown(n: int) -> np.ndarray:  # returns inside a 3 m crown at an exponential depth (0.3 m)
        v = rng.normal(size=(n, 3))
        v /= np.linalg.norm(v, axis=1, keepdims=True)
        v = v[v[:, 2] > -0.2]
        return (
            np.array([10.0, 10.0, 6.0]) + (3.0 - np.minimum(rng.exponential(0.3, len(v)), 3.0))[:, None] * v
        )

    ga, gb = _ground(rng, 80.0), _ground(rng, 80.0)
    ca, cb = crown(3000), crown(3000)
    a, b = np.concatenate([ga, ca]), np.concatenate([gb, cb])
    ac = np.r_[_full(len(ga), GROUND), _full(len(ca), VEG)]
    bc = np.r_[_full(len(gb), GROUND), _full(len(cb), VEG)]
    leaves = _flags(a, ac, b, bc)[len(ga) :]
    assert (leaves == CHANGED).mean() < 0.005
    assert (_flags(a, ac, b, bc, "surface")[len(ga) :] == CHANGED).mean() > 0.02
    cut = _flags(a, ac, gb, _full(len(gb), GROUND))[len(ga) :]
    assert (cut == CHANGED).mean() > 0.98


def test_a_thin_pole_put_up_on_open_ground_is_found_point_by_point() -> None:
    rng = np.random.default_rng(6)
    ga, gb = _ground(rng, 80.0), _ground(rng, 80.0)
    # 24 returns on a 6 m pole, as a flight gives it, and 3 at the height where a few of the ground's
    # points lie at the edge of the rule's reach under them (too few for a plane: not a grazed
    # surface, the ground it stands on)
    reach = LabelParams().surface_test(R).fit_m
    z = np.r_[np.sort(rng.uniform(0.3, 6.0, 24)), reach - np.array([0.0003, 0.0008, 0.0015])]
    pole = np.c_[10.0 + rng.normal(0, 0.05, 27), 10.0 + rng.normal(0, 0.05, 27), z]
    b = np.concatenate([gb, pole])
    bc = np.r_[_full(len(gb), GROUND), _full(27, TEMP)]
    fb = _flags(b, bc, ga, _full(len(ga), GROUND))
    assert (fb[len(gb) :] == CHANGED).all()
    # every class compared by geometry only (a class-agnostic rule): the ground under the pole lies
    # farther below it than beside it
    test = LabelParams(surface_probe=0.7).surface_test(R)
    every = np.ones(256, bool)
    blind = change_flags(b, bc, ga, _full(len(ga), GROUND), R, IGN, Matching(surface=test), every)
    assert (blind[len(gb) :] == CHANGED).all()


def _planes_oracle(q, pts, valid, tol, test, anchors):  # noqa: ANN001, ANN202
    """planes_through written out plainly: every plane through the point, an anchor and another."""
    out = []
    for r in range(len(q)):
        rel = pts[r] - q[r]
        best, normal = 0, None
        for a in range(min(anchors, len(rel))):
            for j in range(a + 1, len(rel)):
                if not (valid[r, a] and valid[r, j]):
                    continue
                n = np.cross(rel[a], rel[j])
                if np.linalg.norm(n) <= 1e-3 * np.linalg.norm(rel[a]) * np.linalg.norm(rel[j]):
                    continue
                n = n / np.linalg.norm(n)
                count = int((valid[r] & (np.abs(rel @ n) <= tol)).sum())
                if count > best:
                    best, normal = count, n
        if best < test.min_fit:
            out.append(False)
            continue
        inl = valid[r] & (np.abs(rel @ normal) <= tol)
        mean = rel[inl].mean(axis=0)
        spread = np.sqrt(((rel[inl] - mean) ** 2).sum(axis=1).mean())
        offset = np.linalg.norm(mean - (mean @ normal) * normal)
        d = np.linalg.norm(rel[inl][:, None] - rel[inl][None], axis=2) + np.diag(np.full(inl.sum(), np.inf))
        own = np.median(d.min(axis=1))
        out.append(
            bool(
                offset <= test.surround * spread and np.linalg.norm(rel[inl], axis=1).min() <= test.gap * own
            )
        )
    return np.array(out)


def test_the_compiled_plane_search_agrees_with_a_plain_one() -> None:
    from siteline.labels.change import ANCHORS, planes_through

    rng = np.random.default_rng(8)
    test = LabelParams().surface_test(R)
    m, k = 300, 12
    q = rng.uniform(-1, 1, (m, 3))
    # half the rows: neighbours on a plane through the point (plus noise and strays), half at random
    normal = rng.normal(size=(m, 3))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    offsets = rng.uniform(-0.5, 0.5, (m, k, 3))
    offsets -= (
        np.einsum("mkc,mc->mk", offsets, normal)[..., None]
        * normal[:, None, :]
        * (np.arange(m) % 2 == 0)[:, None, None]
    )
    pts = q[:, None, :] + offsets + rng.normal(0, 0.01, (m, k, 3))
    valid = rng.random((m, k)) > 0.15
    got = planes_through(q, pts, valid, 0.05, test)
    assert np.array_equal(got, _planes_oracle(q, pts, valid, 0.05, test, ANCHORS))
    assert 20 < got.sum() < m - 20  # both answers occur


def _fence_line(seed: int) -> tuple[np.ndarray, ...]:
    """Two scans at 10 points/m2 of ground across the site's fence line (y = 0) and of a panel standing
    on it (3 points/m2, grazed), classes as ingest gives them: what falls outside (y < 0) is ignored."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(2):
        g = _ground(rng, 10.0, y=(-10.0, 10.0))
        f = _wall(rng, 3.0, x0=4.0, length=12.0, y=0.0, height=2.0)
        xyz = np.concatenate([g, f])
        kind = np.r_[_full(len(g), GROUND), _full(len(f), TEMP)]
        out += [xyz, np.where(xyz[:, 1] >= 0.0, kind, TAX.ignore_id).astype(np.uint8), len(g)]
    return tuple(out)


def test_a_panel_on_the_fence_line_is_ignored_where_only_the_other_scans_outside_returns_hold_it() -> None:
    r = 0.46  # 2.5 x the ground's spacing at 10 points/m2

    def flags(a, ac, b, bc, rule="adaptive"):
        test = LabelParams(rule=rule, surface_probe=0.7).surface_test(r)
        return change_flags(a, ac, b, bc, r, IGN, Matching(surface=test, ground=TAX.ground_lut()))

    kept, gone, before = [], [], []
    for seed in range(5):
        a, ac, na, b, bc, nb = _fence_line(seed)
        inside = slice(na, None)
        panel = ac[inside] == TEMP  # A's panel returns that fall inside the fence
        kept.append(flags(a, ac, b, bc)[inside][panel])
        gone.append(flags(a, ac, b[:nb], bc[:nb])[inside][panel])  # B: the panel taken away
        before.append(flags(a, ac, b, bc, "surface")[inside][panel])
    kept, gone, before = (np.concatenate(x) for x in (kept, gone, before))
    # each scan kept other returns of the panel: those of A's that B kept none beside were changed
    # against B's kept points alone; B's outside returns hold them, so they are ignored
    assert (kept == CHANGED).mean() < 0.04
    assert (kept == IGNORED).mean() > 0.05
    assert (before == CHANGED).mean() > 0.1  # the surface rule: changed
    # a panel taken away is still changed, but for its foot within reach of the ground both sides
    assert (gone == CHANGED).mean() > 0.8
    # ground dug 9 m deep beside the line (B's outside returns within the rule's reach) stays changed
    a, ac, na, b, bc, nb = _fence_line(0)
    rng = np.random.default_rng(5)
    pit = lambda xyz: (xyz[:, 0] > 8) & (xyz[:, 0] < 12) & (xyz[:, 1] > 1) & (xyz[:, 1] < 5)  # noqa: E731
    floor = np.c_[rng.uniform(8, 12, 160), rng.uniform(1, 5, 160), np.full(160, -9.0)]
    b, bc = np.concatenate([b[~pit(b)], floor]), np.r_[bc[~pit(b)], _full(160, GROUND)]
    inside = bc != TAX.ignore_id
    dug = flags(a, ac, b, bc)[pit(a) & (ac == GROUND)]
    alone = flags(a, ac, b[inside], bc[inside])[pit(a) & (ac == GROUND)]  # B's outside returns dropped
    assert (dug == CHANGED).sum() > 50 and np.array_equal(dug, alone)
