"""OpenCVMarkerCamera against CameraEmulator (the simulated camera's frames through a fake VideoCapture)."""

import time

import cv2
import numpy as np
import pytest

from hardware.camera import CameraConfig, CameraEmulator, FakeCapture, OpenCVMarkerCamera
from hardware.interfaces import DeviceError
from layerskin_exp.config import ConfigError
from tests.hardware.conftest import start_realtime_world


@pytest.fixture(scope="module")
def rt():
    """One gripper world for the module; one emulator takes the twin's frames at a time."""
    world = start_realtime_world("gripper")
    yield world
    world.stop()


@pytest.fixture
def emu(rt):
    with CameraEmulator(rt) as e:
        yield e


def collect_frames(cam, n_frames, timeout_s=5.0):
    """Detections of at least n_frames frames (a generous bound, not a timing claim)."""
    out, deadline = [], time.monotonic() + timeout_s
    while len({d.frame_seq for d in out}) < n_frames:
        assert time.monotonic() < deadline, f"only {len(out)} detections"
        time.sleep(0.02)
        out += cam.read_available()
    return out


def wait_for(pred, timeout_s=3.0):
    deadline = time.monotonic() + timeout_s
    while not pred():
        assert time.monotonic() < deadline
        time.sleep(0.01)


def test_the_driver_finds_both_markers_where_the_simulated_camera_does(emu, rt):
    cfg = CameraConfig()
    assert emu.name.startswith("fake-capture:")
    with OpenCVMarkerCamera(cfg, emu.capture_factory) as cam:
        dets = collect_frames(cam, 8)
        img = cam.latest_image()
    by_frame = {}
    for d in dets:
        by_frame.setdefault(d.frame_seq, []).append(d)
    assert all(sorted(d.marker_id for d in ds) == [0, 1] for ds in by_frame.values())
    for ds in by_frame.values():
        # The printed layout, seen independently of any reference: markers 16 mm apart, 5 mm squares.
        p = {d.marker_id: d.pose.position_m * 1e3 for d in ds}
        assert np.linalg.norm(p[1] - p[0]) == pytest.approx(16.0, abs=0.1)
        assert 100 < p[0][2] < 140  # in front of the camera, near its working distance
        twin = {t.marker_id: t for t in emu.twin_detections.get(ds[0].device_t_ns, [])}
        assert set(twin) == {0, 1}  # the twin saw the same frame (same capture time)
        for d in ds:
            assert np.abs(d.pose.position_m - twin[d.marker_id].pose.position_m).max() < 1e-3  # m: within a mm
            assert np.abs(d.corners_px - twin[d.marker_id].corners_px).max() < 0.05
            assert np.isclose(np.linalg.norm(d.pose.orientation_xyzw), 1.0)
    frames = [ds[0] for _, ds in sorted(by_frame.items())]
    dev = np.array([d.device_t_ns for d in frames])
    host = np.array([d.host_t_ns for d in frames])
    assert np.all(np.diff(dev) > 0) and np.all(np.diff(host) > 0)
    # The twin's 30 fps on its own clock (a frame may be skipped when the world's pacer lags).
    periods = np.diff(dev) / 1e6 / (1000 / 30)
    assert np.all(np.abs(periods - np.round(periods)) < 0.15) and np.median(np.round(periods)) == 1
    assert cam.health.received >= 8 and cam.health.lost == 0
    assert img.shape == (cfg.height_px, cfg.width_px) and img.dtype == np.uint8


class NoTimestampCapture(FakeCapture):
    """A backend that gives no frame timestamps."""

    def get(self, prop):
        return 0.0 if prop == cv2.CAP_PROP_POS_MSEC else super().get(prop)


def test_without_backend_timestamps_capture_time_is_receive_time_minus_latency(emu):
    cfg = CameraConfig(latency_ms=70.0)
    with OpenCVMarkerCamera(cfg, lambda: NoTimestampCapture(emu)) as cam:
        dets = collect_frames(cam, 3)
    assert all(d.host_t_ns - d.device_t_ns == 70_000_000 for d in dets)
    assert all(d.pose.device_t_ns == d.device_t_ns for d in dets)


class SlowCapture(FakeCapture):
    """A host that reads the capture slower (10 per s) than the camera makes frames (30 per s)."""

    def read(self):
        time.sleep(0.1)
        return super().read()


def test_frames_a_slow_reader_loses_show_as_gaps_and_are_counted(emu):
    # The ring keeps the newest frames; the driver numbers frames by their capture times, so what
    # the ring overwrote is a gap in frame_seq and lost in the health, not silently skipped.
    cfg = CameraConfig()
    with OpenCVMarkerCamera(cfg, lambda: SlowCapture(emu)) as cam:
        dets = collect_frames(cam, 10, timeout_s=10.0)
        lost = cam.health.lost
    assert emu.overwritten > 0 and lost > 0
    frames = {d.frame_seq: d.device_t_ns for d in dets}
    seq = np.array(sorted(frames))
    dev = np.array([frames[k] for k in seq])
    steps = np.round(np.diff(dev) / (1e9 / cfg.fps))
    assert np.array_equal(np.diff(seq), steps)  # a frame number per frame period of capture time
    assert int(np.sum(steps - 1)) <= lost  # every gap among the frames read is counted


def test_a_capture_that_stops_is_a_fault(emu):
    with OpenCVMarkerCamera(CameraConfig(), emu.capture_factory) as cam:
        collect_frames(cam, 2)
        emu.stall()
        time.sleep(0.1)
        cam.read_available()
        last = cam._last_rx_ns
        # At the rig clock's times: fine within the stall timeout (0.2 s at 30 fps), faulted after.
        assert cam.fault(last + 150_000_000) is None
        assert cam.fault(last + 250_000_000) == "camera stalled: no frame for 250 ms"
        emu.disconnect()
        wait_for(lambda: cam.fault(time.monotonic_ns()) is not None and "capture ended" in cam.fault(0))


def test_a_source_that_does_not_open_or_never_delivers_fails_connect(emu):
    class Closed(FakeCapture):
        def isOpened(self):
            return False

    with pytest.raises(DeviceError, match="camera: cannot open v4l2 source '0'"):
        OpenCVMarkerCamera(CameraConfig(), lambda: Closed(emu)).connect()
    emu.stall()
    cam = OpenCVMarkerCamera(CameraConfig(connect_timeout_s=0.3), emu.capture_factory)
    with pytest.raises(DeviceError, match="no frame from v4l2 source '0' within 0.3 s"):
        cam.connect()
    assert not cam.is_connected


def test_config_checks():
    with pytest.raises(ConfigError, match="hardware.camera.dist_coeffs"):
        CameraConfig(dist_coeffs=(0.1, 0.0, 0.0))
    with pytest.raises(ConfigError, match="hardware.camera.backend"):
        CameraConfig(backend="gstreamer")
    with pytest.raises(ConfigError, match="hardware.camera.stall_timeout_s"):
        CameraConfig(stall_timeout_s=5.0)
