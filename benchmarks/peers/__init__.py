"""One adapter per method: each takes a SceneSpec, an end time and an accuracy knob and returns the final
state and the in-process wall time of the integration only (model construction is timed separately)."""
