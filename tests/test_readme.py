"""The README's Python snippet runs as printed (from the checkout's root, where its paths point)."""
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_the_readme_python_snippet_runs_as_printed(monkeypatch):
    text = (ROOT / "README.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    snippet = next(b for b in blocks if "ln.Simulator(" in b and "ln.ensemble" not in b)
    monkeypatch.chdir(ROOT)
    namespace: dict = {}
    exec(compile(snippet, "README.md", "exec"), namespace)  # noqa: S102 - the README's own code
    sim, res = namespace["sim"], namespace["res"]
    assert sim.state.t == 0.01 and res.t[-1] == 2.0 and res.max_error_estimate <= res.error_goal
