"""The immutable description of a network (like MuJoCo's mjModel): masses, links, force elements, the initial
state; JSON scene files and parametric builders."""
from linknet_core.scene.description import FORCE_ELEMENT_PARAMETERS, ForceElements, Scene, Springs, load_scene
from linknet_core.scene import builders

__all__ = ["Scene", "Springs", "ForceElements", "FORCE_ELEMENT_PARAMETERS", "load_scene", "builders"]
