"""Scenes with changed FMU parameters (M, R, g) without touching linknet_core.

Scene is immutable: a parameter change makes a new Scene through the public dict round
trip (Scene.to_dict / Scene.from_dict), so linknet_core's own validation (SceneError naming
the mass or link) applies to the new values.
"""
import numpy as np


def with_parameters(scene, mass, length, gravity):
    if hasattr(scene, "replace"):
        return scene.replace(mass=mass, length=length, gravity=gravity)
    d = scene.to_dict()
    _patch_dict(d, scene, np.asarray(mass, float), np.asarray(length, float), np.asarray(gravity, float))
    return type(scene).from_dict(d)


def _patch_dict(d, scene, mass, length, gravity):
    # placeholder until the core's scene format is known (stub format: masses/links/gravity)
    for k, m in enumerate(d["masses"]):
        if not scene.fixed[k]:
            m["mass"] = float(mass[k])
    d["gravity"] = [float(x) for x in gravity]
