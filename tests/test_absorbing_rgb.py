"""benchmarks/absorbing_eval.py --rgb: what the colour image says inside an unread region,
measured on seeded synthetic frames (a stain that keeps the surface's grain at reduced
brightness against a void whose shading falls off towards its inside)."""

from __future__ import annotations

import importlib.util
from pathlib import Path
from types import ModuleType

import cv2
import numpy as np

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "absorbing_eval.py"
BOX = (60, 40, 80, 80)


def _script() -> ModuleType:
    spec = importlib.util.spec_from_file_location("absorbing_eval", SCRIPT)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _scene(kind: str, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(grey uint8, depth uint16): textured rubble, an unread disc of radius 35 px."""
    rng = np.random.default_rng(seed)
    grain = cv2.GaussianBlur(rng.normal(0.0, 1.0, (160, 200)).astype(np.float32), (0, 0), 1.5)
    albedo = 0.55 * np.exp(0.25 * grain / grain.std())
    yy, xx = np.mgrid[:160, :200]
    r = np.hypot(xx - 100.0, yy - 80.0)
    disc = r < 35
    if kind == "stain":  # albedo x 0.45: the grain kept, darker
        lum = albedo * np.where(disc, 0.45, 1.0)
    else:  # a void: its walls' grain fades into shading that falls off inwards
        fall = np.clip(r / 35.0, 0.0, 1.0) ** 2
        lum = np.where(disc, 0.06 + albedo * (0.15 + 0.55 * fall), albedo)
        lum = np.where(disc, lum * (0.5 + 0.5 * fall) + (1 - fall) * 0.03, lum)
    lum += rng.normal(0.0, 0.004, lum.shape)
    grey = np.clip(lum * 255.0, 0, 255).astype(np.uint8)
    depth = np.where(disc, 0, 2000).astype(np.uint16)
    return grey, depth


def test_stain_keeps_its_grain_and_brightness_void_darkens_inwards() -> None:
    mod = _script()
    for seed in (1, 2, 3):
        stain = mod.rgb_features(*_scene("stain", seed), BOX)
        void = mod.rgb_features(*_scene("void", seed), BOX)
        assert stain is not None and void is not None
        # The stain: as bright as its albedo factor, flat inside, the rim's grain kept.
        assert abs(stain["brightness"] - 0.45) < 0.05
        assert abs(stain["core_over_edge"] - 1.0) < 0.1
        assert 0.8 < stain["texture"] < 1.2
        # The void: darker, darker towards its inside, less grain than the rim.
        assert void["brightness"] < 0.35
        assert void["core_over_edge"] < 0.7
        assert void["texture"] < 0.8 * stain["texture"]


def test_too_small_a_region_gives_no_features() -> None:
    grey, depth = _scene("stain", 4)
    depth[:] = 2000
    depth[78:82, 98:102] = 0
    assert _script().rgb_features(grey, depth, (96, 76, 8, 8)) is None
