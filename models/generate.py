"""Regenerate the shipped scene files from the parametric builders: python models/generate.py"""
from pathlib import Path

from linknet_core.scene.builders import shipped_scenes

if __name__ == "__main__":
    here = Path(__file__).resolve().parent
    for name, scene in shipped_scenes().items():
        scene.save(here / f"{name}.json")
        print(f"wrote models/{name}.json: K={scene.K}, L={scene.L}")
