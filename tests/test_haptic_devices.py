"""Vendor haptic arms in softenv play, run against simulated SDKs (the real ones need the hardware): the
servo loop at 1 kHz, the axes each way, the force saturation, the refusals that say what to install."""

import sys
import threading
import time
import types

import numpy as np
import pytest

from softenv.cli import main
from softenv.training import play
from softenv.training.inputs import ArmInput
from softenv.haptics.arms import ForceDimensionDevice, ServoDevice, TouchDevice
from softenv.training.hand import haptic_config, workspace
from softenv.training.logs import read_log

WORKSPACE = workspace(haptic_config(None))


def _stylus(t: float) -> tuple[float, float, float]:
    """The simulated hand (m; x right, y up, z toward the user): still for 50 ms (where it starts is the hand's
    start), then push 2 cm away over 0.3 s, then lower 2 cm over 0.3 s."""
    away = -0.02 * float(np.clip((t - 0.05) / 0.3, 0.0, 1.0))
    down = -0.02 * float(np.clip((t - 0.35) / 0.3, 0.0, 1.0))
    return 0.0, down, away


class FakeOpenHaptics:
    """pyOpenHaptics' modules: a scheduler thread calling the servo callback every millisecond, the stylus on
    :func:`_stylus` (OpenHaptics reports mm), and every force set recorded."""

    def __init__(self):
        self.forces, self.started, self.closed = [], None, threading.Event()
        fake = self
        hd = types.ModuleType("pyOpenHaptics.hd")

        def get_transform():
            x, y, z = _stylus(time.perf_counter() - fake.started)
            return [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [x * 1e3, y * 1e3, z * 1e3, 1]]

        hd.get_transform = get_transform
        hd.set_force = lambda force: fake.forces.append(list(force))
        callback = types.ModuleType("pyOpenHaptics.hd_callback")
        callback.hd_callback = lambda function: function
        device = types.ModuleType("pyOpenHaptics.hd_device")

        class HapticDevice:
            def __init__(self, callback, scheduler_type="async"):
                fake.started = time.perf_counter()
                self.thread = threading.Thread(target=self.loop, args=(callback,), daemon=True)
                self.thread.start()

            def loop(self, callback):
                while not fake.closed.is_set():
                    callback()
                    time.sleep(1e-3)

            def close(self):
                fake.closed.set()
                self.thread.join()

        device.HapticDevice = HapticDevice
        package = types.ModuleType("pyOpenHaptics")
        self.modules = {"pyOpenHaptics": package, "pyOpenHaptics.hd": hd, "pyOpenHaptics.hd_callback": callback,
                        "pyOpenHaptics.hd_device": device}


def test_a_touch_drives_a_session_and_feels_its_force(tmp_path, monkeypatch):
    fake = FakeOpenHaptics()
    for name, module in fake.modules.items():
        monkeypatch.setitem(sys.modules, name, module)
    play.headless()
    device = TouchDevice(WORKSPACE, max_force_N=2.0)
    try:
        session = play.run(seconds=1.0, out_dir=tmp_path, realtime=True, screens=False, device=ArmInput(device),
                           echo=lambda s: None)
    finally:
        device.close()
    assert fake.closed.is_set() and device.ticks > 300                  # the fake's 1 ms sleeps, over a second
    log = session.log
    assert log[-1, 1:3] == pytest.approx([-0.02, -0.02], abs=1e-9)      # pushed away: inserted; lowered: pressed
    assert abs(log[-1, 3]) < 1e-12 and abs(log[-1, 4]) < 1e-6           # level wrist, no sweep
    forces = np.array(fake.forces)
    assert np.linalg.norm(forces, axis=1).max() > 0.5                    # the press came back as force ...
    assert np.linalg.norm(forces, axis=1).max() <= 2.0 + 1e-12          # ... saturated at the device's limit
    note = next(tmp_path.glob("session_*.csv")).read_text().splitlines()[1]
    assert "3D Systems Touch (OpenHaptics)" in note and "servo ticks" in note
    _, table = read_log(next(tmp_path.glob("session_*.csv")))
    assert np.allclose(table[:, 1:], log[:, 1:])


def test_force_dimension_axes_and_servo_loop(monkeypatch):
    """Force Dimension's x is toward the user, y right, z up: the position is turned into OpenHaptics' frame
    for the hand, and the rendered force (world x, y, z) goes back in the SDK's own axes."""
    calls = {"forces": [], "closed": False, "enabled": None}
    dhd = types.ModuleType("forcedimension_core.dhd")
    dhd.open = lambda: 0
    dhd.enableForce = lambda on: calls.update(enabled=on)
    position = [0.0, 0.0, 0.0]

    def get_position(out):
        out[:] = position
        return 0

    dhd.getPosition = get_position
    dhd.setForce = lambda f: calls["forces"].append(list(f))
    dhd.close = lambda: calls.update(closed=True)
    package = types.ModuleType("forcedimension_core")
    package.dhd = dhd
    monkeypatch.setitem(sys.modules, "forcedimension_core", package)
    monkeypatch.setitem(sys.modules, "forcedimension_core.dhd", dhd)
    device = ForceDimensionDevice(WORKSPACE, scale=1.0, force_scale=0.5, max_force_N=100.0)
    try:
        time.sleep(0.05)                                                 # the origin: the first ticks at 0
        position[:] = [-0.02, 0.01, -0.015]                             # 2 cm away from the user, 1 cm right, 1.5 cm down
        time.sleep(0.05)
        assert np.allclose(device.hand_pose(), [-0.02, -0.015, 0.0, 0.01])
        device.feel(np.array([1.0, 2.0, 3.0]))
        time.sleep(0.05)
        assert np.allclose(calls["forces"][-1], [0.5, 1.0, 1.5])         # world (x, y, z) = the SDK's axes, scaled
    finally:
        device.close()
    assert calls["enabled"] is True and calls["closed"] and calls["forces"][-1] == [0.0, 0.0, 0.0]
    assert device.ticks > 50


def test_missing_sdks_and_absent_devices_are_refused_saying_what_to_install(monkeypatch, tmp_path, capsys):
    for name in ("pyOpenHaptics", "pyOpenHaptics.hd", "pyOpenHaptics.hd_callback", "pyOpenHaptics.hd_device",
                 "forcedimension_core", "forcedimension_core.dhd"):
        monkeypatch.setitem(sys.modules, name, None)                     # as if not installed
    with pytest.raises(ValueError, match=r"pip install 'softenv\[touch\]'"):
        TouchDevice(WORKSPACE)
    with pytest.raises(ValueError, match=r"pip install 'softenv\[forcedimension\]'"):
        ForceDimensionDevice(WORKSPACE)
    assert main(["play", "--headless", "--device", "touch", "--out", str(tmp_path / "s")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "softenv[touch]" in err and not (tmp_path / "s").exists()
    assert main(["play", "--headless", "--device", "touch", "--bridge", "0"]) == 2
    assert "give one" in capsys.readouterr().err
    dhd = types.ModuleType("forcedimension_core.dhd")
    dhd.open, dhd.errorGetLastStr = (lambda: -1), (lambda: "no device found")
    monkeypatch.setitem(sys.modules, "forcedimension_core", types.SimpleNamespace(dhd=dhd))
    monkeypatch.setitem(sys.modules, "forcedimension_core.dhd", dhd)
    with pytest.raises(ValueError, match="no Force Dimension device opened: no device found"):
        ForceDimensionDevice(WORKSPACE)


@pytest.mark.parametrize("name", ["scale", "force_scale", "max_force_N"])
@pytest.mark.parametrize("value", [0.0, -1.0, float("nan"), float("inf")])
def test_a_bad_mapping_is_refused_by_name(name, value):
    with pytest.raises(ValueError, match=f"{name}="):
        ServoDevice(WORKSPACE, **{name: value})
