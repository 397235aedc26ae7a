"""Regenerate the shipped scene files from the parametric builders: python models/generate.py

models/*.json are the shipped scenes; models/degenerate/*.json the degenerate nets the methods do not yet carry
through (builders.degenerate_scenes)."""
from pathlib import Path

from linknet_core.scene.builders import degenerate_scenes, shipped_scenes

if __name__ == "__main__":
    here = Path(__file__).resolve().parent
    for folder, scenes in ((here, shipped_scenes()), (here / "degenerate", degenerate_scenes())):
        folder.mkdir(exist_ok=True)
        for name, scene in scenes.items():
            scene.save(folder / f"{name}.json")
            print(f"wrote {(folder / name).relative_to(here.parent)}.json: K={scene.K}, L={scene.L}")
