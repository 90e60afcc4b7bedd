"""Bad arguments raise clear Python exceptions (never a crash); odd layouts are handled."""

import threading
import time

import numpy as np
import pytest

import unispine
from conftest import GEOMETRY, look_at_camera, params, scene

VM, K, W, H = look_at_camera()


def call(ps, **kw):
    args = dict(viewmats=VM, Ks=K, width=W, height=H)
    args.update(kw)
    return unispine.rasterize(*ps, **args)


@pytest.fixture
def ps():
    return params(scene(20, seed=1, extent=9.0))


@pytest.mark.parametrize("i,shape", [(0, (20, 2)), (1, (20, 3)), (2, (19, 3)), (3, (20, 1)),
                                     (4, (20, 15))])
def test_wrong_shapes(ps, i, shape):
    ps[i] = np.zeros(shape)
    with pytest.raises(ValueError, match="must have shape"):
        call(ps)


def test_wrong_dtypes(ps):
    ps[2] = ps[2].astype(np.float32)
    with pytest.raises(TypeError, match="log_scales.*float64"):
        call(ps)
    ps[2] = ps[2].astype(np.int64)
    with pytest.raises(TypeError, match="log_scales"):
        call(ps)
    with pytest.raises(TypeError, match="float32 or float64"):
        call([p.astype(np.int32) for p in ps])
    with pytest.raises(TypeError, match="numpy array"):
        call([p.tolist() for p in ps])


@pytest.mark.parametrize("i", range(5))
def test_non_finite_values(ps, i):
    ps[i] = ps[i].copy()
    ps[i].flat[3] = np.nan if i % 2 else np.inf
    with pytest.raises(ValueError, match="non-finite"):
        call(ps)


def test_non_contiguous_arrays_give_the_same_bits(ps):
    want = call(ps)[0]
    strided = [np.asfortranarray(p) for p in ps]
    strided[0] = np.repeat(ps[0], 2, axis=0)[::2]         # a strided view
    strided[4] = np.ascontiguousarray(ps[4][:, ::-1])[:, ::-1]  # negative strides
    assert not strided[0].flags.c_contiguous and not strided[4].flags.c_contiguous
    assert np.array_equal(call(strided)[0], want)


def test_bad_cameras_and_settings(ps):
    scaled = VM.copy()
    scaled[0, :3, :3] *= 2
    with pytest.raises(ValueError, match="rotation"):
        call(ps, viewmats=scaled)
    with pytest.raises(ValueError, match="last row"):
        call(ps, viewmats=VM * 2)
    with pytest.raises(ValueError, match="Ks"):
        call(ps, Ks=np.zeros((1, 3, 3)))
    with pytest.raises(ValueError, match="shape"):
        call(ps, Ks=np.zeros((2, 3, 3)))
    with pytest.raises(ValueError, match="camera_model"):
        call(ps, camera_model="fisheye")
    with pytest.raises(ValueError, match="color_mode"):
        call(ps, color_mode="rgb")
    with pytest.raises(ValueError, match="active_features"):
        call(ps, active_features=5)
    with pytest.raises(ValueError, match="background"):
        call(ps, background=float("nan"))
    with pytest.raises(ValueError, match="cameras"):
        unispine.rasterize(*ps)
    with pytest.raises(ValueError, match="not both"):
        call(ps, geometry=GEOMETRY, angles=0.0)
    bad = dict(GEOMETRY, DSD=-1.0)
    with pytest.raises(ValueError, match="DSD"):
        unispine.rasterize(*ps, geometry=bad, angles=0.0)
    with pytest.raises(ValueError, match="finite"):
        unispine.rasterize(*ps, geometry=GEOMETRY, angles=[0.0, float("inf")])
    with pytest.raises(ValueError, match="d_image"):
        unispine.rasterize_vjp(*ps, VM, K, W, H, d_image=np.zeros((1, H, W + 1)))


def test_other_functions_refuse_bad_arguments():
    img = np.random.default_rng(0).random((20, 24))
    with pytest.raises(ValueError, match="shape"):
        unispine.ssim(img, img[:, :-1])
    with pytest.raises(TypeError, match="float64"):
        unispine.ssim(img, img.astype(np.float32))
    with pytest.raises(ValueError, match="data_term"):
        unispine.loss(img, img, data_term="l2")
    with pytest.raises(ValueError, match="lambda_dssim"):
        unispine.loss(img, img, lambda_dssim=2.0)
    with pytest.raises(ValueError, match="non-finite"):
        unispine.loss(img, np.where(img > 0.5, np.nan, img))
    vol = np.zeros((32, 32, 31))
    with pytest.raises(ValueError, match="nVoxel"):
        unispine.drr(vol, GEOMETRY, 0.0)
    with pytest.raises(ValueError, match="method"):
        unispine.drr(np.zeros((32, 32, 32)), GEOMETRY, 0.0, method="joseph")
    with pytest.raises(ValueError, match="no golden folder"):
        unispine.golden_cases("eq99")


def test_empty_scene_renders_background():
    ps = [np.zeros((0,) + s) for s in [(3,), (4,), (3,), (), (16,)]]
    img, trans, n = call(ps, background=0.5)
    assert np.all(img == 0.5) and np.all(trans == 1) and np.all(n == 0)


def test_the_gil_is_released_during_a_render():
    """A pure-Python thread keeps running while another thread renders."""
    sc = scene(20000, seed=2, extent=30.0)
    ps = params(sc)
    geo = dict(GEOMETRY, nDetector=[256, 256], dDetector=[0.5, 0.5])
    angles = np.linspace(0, 3, 4)
    t0 = time.perf_counter()
    unispine.rasterize(*ps, geometry=geo, angles=angles)
    single = time.perf_counter() - t0

    ticks = []
    done = threading.Event()

    def ticker():
        while not done.is_set():
            ticks.append(time.perf_counter())
            time.sleep(0.001)

    th = threading.Thread(target=ticker)
    th.start()
    t0 = time.perf_counter()
    unispine.rasterize(*ps, geometry=geo, angles=angles)
    t1 = time.perf_counter()
    done.set()
    th.join()
    during = [t for t in ticks if t0 < t < t1]
    # With the GIL held the ticker would not run at all during the call.
    assert single > 0.02, "the render is long enough to observe"
    assert len(during) >= 5, (len(during), t1 - t0)


# Calls whose inputs or outputs exceed the module's 8 GiB cap raise ValueError naming the
# argument, before anything large is allocated (the interpreter is not aborted).
def test_huge_image_is_refused(ps):
    with pytest.raises(ValueError, match="width.*height.*8 GiB"):
        call(ps, width=32768, height=32768)


def test_huge_broadcast_camera_count_is_refused(ps):
    vms = np.broadcast_to(VM, (10**6, 4, 4))
    ks = np.broadcast_to(K, (10**6, 3, 3))
    with pytest.raises(ValueError, match="viewmats.*10+ cameras.*8 GiB"):
        call(ps, viewmats=vms, Ks=ks)


def test_huge_broadcast_angles_are_refused(ps):
    angles = np.broadcast_to(np.float64(0.0), (10**8,))
    with pytest.raises(ValueError, match="angles.*100000000 views.*8 GiB"):
        unispine.rasterize(*ps, geometry=GEOMETRY, angles=angles)
    vol = np.zeros((4, 4, 4))
    with pytest.raises(ValueError, match="angles.*100000000 views.*8 GiB"):
        unispine.drr(vol, GEOMETRY, angles)


def test_huge_broadcast_ssim_inputs_are_refused():
    img = np.broadcast_to(np.float64(0.5), (10**5, 10**5))
    with pytest.raises(ValueError, match="img1.*8 GiB"):
        unispine.ssim(img, img)
