"""Import structure of linknet_core: package-level edges against a layer order, module cycles (lazy imports
included), the largest files and functions. python3 -m benchmarks.import_structure [ROOT] (docs/architecture.md)"""
import ast, os, sys, collections
base = sys.argv[1] if len(sys.argv) > 1 else "."
root = os.path.join(base, "linknet_core")
# the data flow, leaves first: the tolerances and the C binding, errors and outputs, the description, its analysis,
# the reference physics, the run's accuracy rules, the methods, the commands' argument types, the native fast path,
# the driver, and what uses it (symbolic checks, ensembles, pictures, the command line)
LAYERS = ["tolerances", "clib", "errors", "output", "version", "state", "scene", "structure", "dynamics", "accuracy",
          "integrators", "options", "native", "simulator", "symbolic", "ensemble", "visual", "cli", "root"]
mods = {}
for dp, dn, fn in os.walk(root):
    for f in fn:
        if f.endswith(".py"):
            p = os.path.join(dp, f)
            m = os.path.relpath(p, base)[:-3].replace("/", ".")
            if m.endswith(".__init__"):
                m = m[:-9]
            mods[m] = p
edges = collections.defaultdict(set)
for m, p in mods.items():
    for n in ast.walk(ast.parse(open(p).read())):
        if isinstance(n, ast.ImportFrom) and n.module and n.module.startswith("linknet_core"):
            for a in n.names:
                if f"{n.module}.{a.name}" in mods:
                    edges[m].add(f"{n.module}.{a.name}")
                elif n.module in mods:
                    edges[m].add(n.module)
        elif isinstance(n, ast.Import):
            for a in n.names:
                if a.name in mods:
                    edges[m].add(a.name)
def pkg(m):
    parts = m.split(".")
    return parts[1] if len(parts) > 1 else "root"
up = []
for a, bs in edges.items():
    for b in bs:
        pa, pb = pkg(a), pkg(b)
        if pa != pb and pa in LAYERS and pb in LAYERS and LAYERS.index(pb) > LAYERS.index(pa) and pa != "root":
            up.append((a, b))
print(f"upward imports ({len(up)}):")
for a, b in sorted(up):
    print(f"  {a} -> {b}")
sys.setrecursionlimit(10000)
index, low, st, on, sccs, counter = {}, {}, [], set(), [], [0]
def sc(v):
    index[v] = low[v] = counter[0]; counter[0] += 1; st.append(v); on.add(v)
    for w in edges.get(v, ()):
        if w not in index:
            sc(w); low[v] = min(low[v], low[w])
        elif w in on:
            low[v] = min(low[v], index[w])
    if low[v] == index[v]:
        c = []
        while True:
            w = st.pop(); on.discard(w); c.append(w)
            if w == v:
                break
        if len(c) > 1:
            sccs.append(sorted(c))
for v in list(mods):
    if v not in index:
        sc(v)
print(f"module cycles ({len(sccs)}):")
for c in sccs:
    print("  " + " <-> ".join(c))
sizes = sorted(((sum(1 for _ in open(p)), m) for m, p in mods.items()), reverse=True)[:5]
print("largest files:", ", ".join(f"{m} {n}" for n, m in sizes))
funcs = []
for m, p in mods.items():
    for n in ast.walk(ast.parse(open(p).read())):
        if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)):
            funcs.append((n.end_lineno - n.lineno + 1, f"{m}.{n.name}"))
print("largest functions:", ", ".join(f"{f} {n}" for n, f in sorted(funcs, reverse=True)[:5]))
