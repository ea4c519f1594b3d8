"""Moving layers (mlaa_stream.temporal.layers): known answers on seeded textures moved by known maps, and the
TSS stage on a turning object over a still background (the bench's rotation scene, 8x8 supersampled truth)."""
from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from mlaa_stream.bench.temporal import exact_motion, scene_mover, scene_rotation
from mlaa_stream.spatial.filter import Filter
from mlaa_stream.temporal import layers as L
from mlaa_stream.temporal.stage import Pyramid
from mlaa_stream.temporal.motion_ring import MotionRing
from mlaa_stream.temporal.tss import TSSStage
from mlaa_stream.yardstick import metrics as M

H, W = 144, 240
CX, CY, RADIUS = 130.3, 70.6, 40.0


def _texture(seed: int, h: int = H, w: int = W) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return cv2.resize(rng.uniform(0, 255, (h // 8, w // 8)).astype(np.float32), (w, h), interpolation=cv2.INTER_CUBIC)


def _turn(deg: float) -> np.ndarray:
    """3x3: a pixel of the disc turned by `deg` about (CX, CY) -> where it was before."""
    a = math.radians(-deg)
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, CX - c * CX + s * CY], [s, c, CY - s * CX - c * CY], [0.0, 0.0, 1.0]])


def _disc_frames(degrees: list[float]) -> tuple[list[np.ndarray], np.ndarray]:
    """uint8 frames: a still textured background and a textured disc turned by each angle (degrees) about its centre;
    and the disc's mask."""
    bg, disc = _texture(1), _texture(2)
    ys, xs = np.mgrid[0:H, 0:W]
    mask = np.hypot(xs - CX, ys - CY) <= RADIUS
    frames = []
    for d in degrees:
        m = _turn(d)
        turned = cv2.warpAffine(disc, m[:2], (W, H), flags=cv2.INTER_CUBIC | cv2.WARP_INVERSE_MAP,
                                borderMode=cv2.BORDER_REFLECT)
        frames.append(np.clip(np.where(mask, turned, bg), 0, 255).astype(np.uint8))
    return frames, mask


def _offsets(m: np.ndarray, mask: np.ndarray) -> np.ndarray:
    ys, xs = np.nonzero(mask)
    p = np.stack([xs, ys, np.ones_like(xs)], -1).astype(np.float64) @ m.T
    return p[:, :2] / p[:, 2:3] - np.stack([xs, ys], -1)


def _dis():
    dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_FAST)

    def flow(a, b, start):
        init = np.empty(a.shape[:2] + (2,), np.float32)
        init[...] = start
        return dis.calc(a, b, init)
    return flow


def test_affine_steps_recover_a_turning_layer():
    """Known answer (inverse-compositional affine steps at a layer's points): from no motion, the map of a disc turned
    by 1.5 degrees (1 px at its rim) is found within 0.04 px over the disc (uint8 frames: their rounding bounds it)."""
    frames, mask = _disc_frames([0.0, 1.5])
    prev, cur = (cv2.GaussianBlur(f.astype(np.float32), (0, 0), 1.0) for f in frames)
    gx = cv2.Sobel(cur, cv2.CV_32F, 1, 0, ksize=3, scale=0.125)
    gy = cv2.Sobel(cur, cv2.CV_32F, 0, 1, ksize=3, scale=0.125)
    inner = cv2.erode(mask.astype(np.uint8), np.ones((7, 7), np.uint8)) > 0
    pts = L.LayerPoints(cur, inner, gx, gy)
    m, level = pts.refine(prev, np.eye(3), 6)
    err = np.abs(_offsets(m, inner) - _offsets(_turn(1.5), inner)).max()
    assert err < 0.04, err
    assert level < 1.0
    assert np.abs(_offsets(np.eye(3), inner) - _offsets(_turn(1.5), inner)).max() > 0.9


def test_find_layers_separates_a_turning_disc_from_a_still_background():
    """One layer: its map within 0.08 px of the disc's over the disc (the blur mixes the still background into the
    rim's points: 0.03 px from points inside the disc, above), its texels the disc's rim and not the still background
    beyond the label growth."""
    frames, mask = _disc_frames([0.0, 1.5])
    prev, cur = (Pyramid.of(f, False) for f in frames)
    found = L.find_layers(prev, cur, (0.0, 0.0), _dis())
    assert found is not None
    layers, unexplained = found
    assert len(layers) == 1
    layer = layers[0]
    inner = cv2.erode(mask.astype(np.uint8), np.ones((7, 7), np.uint8)) > 0
    assert np.abs(_offsets(layer.affine, inner) - _offsets(_turn(1.5), inner)).max() < 0.08
    rim = mask & (np.hypot(*np.mgrid[0:H, 0:W][::-1] - np.array([CX, CY])[:, None, None]) > RADIUS - 12)
    assert layer.texels[rim].mean() > 0.8
    far = ~cv2.dilate(mask.astype(np.uint8), np.ones((9, 9), np.uint8)).astype(bool)
    assert layer.texels[far].mean() < 0.01
    assert not unexplained.any()


def test_no_layers_where_nothing_or_the_whole_frame_moves():
    frames, _ = _disc_frames([0.0, 0.0])
    a, b = (Pyramid.of(f, False) for f in frames)
    assert L.find_layers(a, b, (0.0, 0.0), _dis()) is None
    # the whole frame zooming (a dolly): more than LAYER_MAX_SHARE changes
    tex = _texture(3)
    zoom = cv2.warpAffine(tex, cv2.getRotationMatrix2D((W / 2, H / 2), 0.0, 1.03), (W, H), flags=cv2.INTER_CUBIC)
    a, b = (Pyramid.of(np.clip(f, 0, 255).astype(np.uint8), False) for f in (tex, zoom))
    assert L.find_layers(a, b, (0.0, 0.0), _dis()) is None


def test_ring_fields_keep_the_background_exact_and_follow_the_layer():
    """Over four frames of the disc turning 1 degree per frame: every ring frame's field is the still background's
    0 exactly away from the disc, and within 0.15 px of the disc's composed turn on its inner texels (0.05 on
    average)."""
    frames, mask = _disc_frames([0.0, 1.0, 2.0, 3.0])
    ring = MotionRing(frames=8)
    fm = None
    for i, f in enumerate(frames):
        fm = ring.push(Pyramid.of(f, False), i, fresh=i == 0)
    assert fm.decision.model == "layers" and fm.decision.measures["layers"] == 1
    far = ~cv2.dilate(mask.astype(np.uint8), np.ones((9, 9), np.uint8)).astype(bool)
    inner = cv2.erode(mask.astype(np.uint8), np.ones((9, 9), np.uint8)) > 0
    for e in fm.entries[:-1]:
        age = 3 - e.index
        assert np.array_equal(e.field[far], np.zeros_like(e.field[far]))
        err = np.abs(e.field[inner] - _offsets(_turn(float(age)), inner))
        assert err.max() < 0.15 and err.mean() < 0.05, (age, err.max(), err.mean())


@pytest.fixture(scope="module")
def rotation():
    sc = scene_rotation(8, 480, 270)
    with Filter(None, bgr=False) as f:
        spatial = [f.process(x) for x in sc.inputs]
    return sc, spatial


def test_turning_object_takes_samples_and_removes_more_error(rotation):
    """The bench's rotation scene (a square and a 0.8-px bar turning 0.5 degrees per frame over a still background):
    layers from the second frame on, and more error removed and a steadier output than the spatial filter alone
    (8 frames, mostly warm-up: 0.953 / 0.210 against 0.948 / 0.221; the 24-frame bench: docs/temporal_bench.md)."""
    sc, spatial = rotation
    with TSSStage(bgr=False) as stage:
        outs = np.stack([stage(f, s, i) for i, (f, s) in enumerate(zip(sc.inputs, spatial))])
    assert [r["model"] for r in stage.stats[1:]] == ["layers"] * 7
    sp = np.stack(spatial)
    assert M.error_removed(outs, sc.inputs, sc.truths) > M.error_removed(sp, sc.inputs, sc.truths) + 0.003
    assert M.temporal_error(outs, sc.inputs, sc.truths) < M.temporal_error(sp, sc.inputs, sc.truths) - 0.005


def test_layers_numpy_backend_is_the_reference(rotation):
    sc, spatial = rotation
    a, b = TSSStage(bgr=False), TSSStage(bgr=False, backend="numpy")
    for i, (f, s) in enumerate(zip(sc.inputs[:5], spatial[:5])):
        assert np.array_equal(a(f, s, i), b(f, s, i)), i
    assert a.stats[-1]["model"] == "layers"


def test_exact_motion_of_the_bench_rotation_is_what_the_layer_finds(rotation):
    """The layer's map of the bench rotation (1-spp frames) matches the scene's exact motion within 0.15 px at its
    points (0.06 on average)."""
    sc, _ = rotation
    ex = np.vstack([exact_motion("rotation", 480, 270).astype(np.float64), [0, 0, 1]])
    for i in (1, 4, 7):
        prev, cur = (Pyramid.of(f, False) for f in sc.inputs[i - 1:i + 1])
        found = L.find_layers(prev, cur, (0.0, 0.0), _dis())
        assert found is not None and len(found[0]) == 1
        layer = found[0][0]
        pts = np.stack([layer.points.xs, layer.points.ys, np.ones(layer.points.count)], -1)
        err = np.hypot(*((pts @ layer.affine.T)[:, :2] - (pts @ ex.T)[:, :2]).T)
        assert err.max() < 0.15 and err.mean() < 0.06, (i, err.max(), err.mean())


def test_layers_lookahead_reads_the_frames_ahead_and_matches_the_reference(rotation):
    """With look-ahead, layer frames take the next frames' samples too (their maps refined directly), the shot's first
    frame included (its layers found against the frame after it), device and numpy reference bit for bit, and the
    output is steadier than without."""
    sc, spatial = rotation
    n = len(sc.inputs)
    a, b = TSSStage(bgr=False, lookahead=2), TSSStage(bgr=False, lookahead=2, backend="numpy")
    outs = []
    for i, (f, s) in enumerate(zip(sc.inputs, spatial)):
        fut = sc.inputs[i + 1:i + 3]
        out = a(f, s, i, future=fut)
        if i < 5:
            assert np.array_equal(out, b(f, s, i, future=fut)), i
        outs.append(out)
    assert [r["lookahead"] for r in a.stats[:n - 2]] == [2] * (n - 2)
    assert a.stats[0]["model"] == "reset" and a.stats[0]["samples_share"] > 0.01   # the first frame reads ahead too
    assert {r["model"] for r in a.stats[1:]} == {"layers"}
    with TSSStage(bgr=False) as causal:
        plain = np.stack([causal(f, s, i) for i, (f, s) in enumerate(zip(sc.inputs, spatial))])
    assert M.temporal_error(np.stack(outs), sc.inputs, sc.truths) < M.temporal_error(plain, sc.inputs, sc.truths)


def _wheel(n: int, w: int = 480, h: int = 270):
    """A wheel (a disc with nine 3-px spokes) turning 0.5 degrees per frame over the bench pan's still background:
    one translation fitted to it is pulled to ~0.26 px per frame."""
    from mlaa_stream.bench.temporal import _pan_layers
    from mlaa_stream.yardstick.scenes import Layer, build_scene, ellipse, rotated_rect
    cx, cy, r = w * 0.62 + 0.21, h * 0.5 + 0.13, h * 0.42
    frames = []
    for t in range(n):
        ang = 0.5 * t
        spokes = tuple(rotated_rect(cx + 0.5 * r * math.cos(math.radians(a + ang)),
                                    cy + 0.5 * r * math.sin(math.radians(a + ang)), r * 0.9, 3.0, a + ang)
                       for a in range(0, 180, 20))
        frames.append(_pan_layers(w, h, 0, 0) + [Layer((ellipse(cx, cy, r, r),), (70, 70, 80)),
                                                 Layer(spokes, (230, 200, 60))])
    return build_scene("wheel", "wheel", frames, w, h)


def test_still_background_under_a_turning_wheel_is_not_a_pan():
    """choose_model explains the wheel over a still background by one translation of ~0.26 px per frame; from the
    ring's third frame (STILL_AGE) TSS takes it as a still background and a layer (Euclidean: the spokes fix no
    scale), level with the spatial filter (with the translation, 16 frames: error removed 0.488 against 0.508,
    damage 0.31 against 0.24)."""
    from mlaa_stream.temporal.stage import choose_model
    sc = _wheel(8)
    a, b = (Pyramid.of(f, False) for f in sc.inputs[2:4])
    assert choose_model(a, b).model == "global" and math.hypot(*choose_model(a, b).translation) > 0.2
    with Filter(None, bgr=False) as f:
        spatial = np.stack([f.process(x) for x in sc.inputs])
    with TSSStage(bgr=False) as stage:
        outs = np.stack([stage(f, s, i) for i, (f, s) in enumerate(zip(sc.inputs, spatial))])
    assert [r["model"] for r in stage.stats[3:]] == ["layers"] * 5
    assert all(r["still_background"] for r in stage.stats[3:])
    found = L.find_layers(a, b, (0.0, 0.0), _dis())
    assert found is not None and found[0][0].dof == 3
    # within 0.001 (the ring's first two frames still take the pulled translation)
    assert M.error_removed(outs, sc.inputs, sc.truths) >= M.error_removed(spatial, sc.inputs, sc.truths) - 0.001
    assert M.damage(outs, sc.inputs, sc.truths, sc.edges) <= M.damage(spatial, sc.inputs, sc.truths, sc.edges) + 0.005


def test_a_pan_stays_a_pan():
    """The still-background test does not take the bench pan (whose 1-spp frames match better unmoved frame to frame:
    its near-horizontal edges jump a row now and then) for a still background: one translation every frame."""
    from mlaa_stream.bench.temporal import scene_pan
    sc = scene_pan(8, 480, 270)
    with TSSStage(bgr=False) as stage:
        for i, f in enumerate(sc.inputs):
            stage(f, f, i)
    assert [r["model"] for r in stage.stats[1:]] == ["global"] * 7


def test_no_layers_where_they_cover_less_than_the_minimum_share():
    """The turning disc's layer takes ~16 % of the frame: found with the default minimum (1 %), not with a minimum
    above its share (what the bench's timing frames meet: two 0.1 % layers, once 200 ms per 1080p frame)."""
    frames, _ = _disc_frames([0.0, 1.5])
    a, b = (Pyramid.of(f, False) for f in frames)
    found = L.find_layers(a, b, (0.0, 0.0), _dis())
    assert found is not None and 0.1 < found[0][0].texels.mean() < 0.25
    share, L.LAYER_MIN_SHARE = L.LAYER_MIN_SHARE, 0.3
    try:
        assert L.find_layers(a, b, (0.0, 0.0), _dis()) is None
    finally:
        L.LAYER_MIN_SHARE = share


def test_a_map_locked_to_the_stripes_under_a_mover_is_no_layer(monkeypatch):
    """The bench's fast mover (a box moving 16.7 px per frame over slanted stripes of a 14-px period): the layer fit
    locks to the stripes' period, not the box (~14 px), and leaves over LAYER_MISFIT of the layer's texels unexplained
    along the box's outline; such a layer is refused (with it TSS was less steady than spatial only on the 24-frame
    scene: temporal error 0.430 against 0.385)."""
    sc = scene_mover(24, 480, 270)
    prev, cur = (Pyramid.of(f, False) for f in sc.inputs[11:13])
    assert L.find_layers(prev, cur, (0.0, 0.0), _dis()) is None
    monkeypatch.setattr(L, "LAYER_MISFIT", 1.0)
    found = L.find_layers(prev, cur, (0.0, 0.0), _dis())
    assert found is not None
    layer = found[0][0]
    ys, xs = np.nonzero(layer.texels)
    centre = np.array([xs.mean(), ys.mean(), 1.0])
    moved = (layer.affine @ centre)[:2] - centre[:2]
    step = 384 / 23
    assert abs(moved[0] * cur.flow_scale + step) > 1.5   # the refused map is px off the box's motion


def test_covered_background_is_where_the_layer_was_in_the_ring_frame():
    """Known answer: a square layer whose map moves it 6 texels left and 2 up per frame (current -> ring frame:
    x + 6, y + 2) over a still background. In that ring frame the square sat 6 right and 2 down of where it is now,
    so the background texels there (outside the square now) are covered and take no samples; the field keeps the
    background's 0 elsewhere and the layer's offset on the square."""
    h, w = 40, 60
    core = np.zeros((h, w), bool)
    core[10:20, 10:25] = True
    texels = cv2.dilate(core.view(np.uint8), np.ones((3, 3), np.uint8)) > 0   # the labels grown by LAYER_GROW
    pts = L.LayerPoints(np.ones((h, w), np.float32), texels, np.ones((h, w), np.float32),
                        np.ones((h, w), np.float32))
    move = L.translation_map((6.0, 2.0))
    layer = L.Layer(texels, pts, move, 6, core)
    covered = L._covered((h, w), (0.0, 0.0), [layer], [move], 1)
    was = np.zeros((h, w), bool)
    was[12:22, 16:31] = True          # the core carried by the map into the ring frame
    np.testing.assert_array_equal(covered, was & ~texels)
    field = L._field((h, w), (0.0, 0.0), np.array([], np.int64), [layer], [move], 1)
    assert np.isnan(field[was & ~texels]).all()
    assert np.array_equal(field[texels], np.broadcast_to(np.float32([6.0, 2.0]), (int(texels.sum()), 2)))
    rest = ~(was | texels)
    assert np.array_equal(field[rest], np.zeros((int(rest.sum()), 2), np.float32))
    assert L._covered((h, w), (0.0, 0.0), [layer], [None], 1) is None   # no map: nothing known covered
