"""The package's layout rules: imports flow one way, nobody inside imports the root,
no module imports another that imports it back."""

import ast
from pathlib import Path

PKG = Path(__file__).resolve().parents[1] / "sknarx"


def module_name(path: Path) -> str:
    parts = path.relative_to(PKG.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports(path: Path) -> set[str]:
    """Absolute names of the sknarx modules a file imports (at any depth, lazily or not)."""
    name = module_name(path)
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if not target.startswith("sknarx"):
                continue
            if node.module is None:  # "from . import x": x is a submodule or a root name
                for alias in node.names:
                    sub = f"{target}.{alias.name}"
                    found = (PKG.parent / sub.replace(".", "/")).with_suffix(".py").exists() \
                        or (PKG.parent / sub.replace(".", "/")).is_dir()
                    out.add(sub if found else target)
            else:
                out.add(target)
        elif isinstance(node, ast.Import):
            out.update(a.name for a in node.names if a.name.startswith("sknarx"))
    out.discard(name)
    return out


MODULES = {module_name(p): imports(p) for p in PKG.rglob("*.py")}


def test_nobody_inside_imports_the_package_root():
    offenders = {m: sorted(i) for m, i in MODULES.items() if "sknarx" in i and m != "sknarx"}
    assert not offenders, offenders


def test_the_identification_core_depends_on_no_later_stage():
    for m, deps in MODULES.items():
        if m.startswith("sknarx.narx"):
            bad = [d for d in deps if d.startswith(("sknarx.rotor", "sknarx.gap", "sknarx.io",
                                                    "sknarx.reproduce", "sknarx.cli"))]
            assert not bad, (m, bad)
        if m.startswith("sknarx.rotor"):
            bad = [d for d in deps if d.startswith(("sknarx.narx", "sknarx.gap",
                                                    "sknarx.reproduce", "sknarx.cli"))]
            assert not bad, (m, bad)


def _owner(mod: str) -> str:
    """The room a module belongs to: its subpackage, or itself at the top level."""
    parts = mod.split(".")
    return ".".join(parts[:2])


def test_no_import_cycle_between_rooms():
    graph: dict[str, set[str]] = {}
    for m, deps in MODULES.items():
        a = _owner(m)
        if a == "sknarx":
            continue
        graph.setdefault(a, set()).update(
            _owner(d) for d in deps if _owner(d) not in (a, "sknarx"))
    seen, stack = set(), []

    def visit(node):
        if node in stack:
            raise AssertionError("import cycle: " + " -> ".join(stack[stack.index(node):]
                                                                 + [node]))
        if node in seen:
            return
        stack.append(node)
        for nxt in graph.get(node, ()):
            visit(nxt)
        stack.pop()
        seen.add(node)

    for node in graph:
        visit(node)


def test_no_pipeline_module_imports_the_test_equipment():
    # sknarx.testing draws trials from the package's own simulator: a diagnosis that
    # reached for it would be validating itself on its own model
    users = sorted(m for m, deps in MODULES.items()
                   if "sknarx.testing" in deps and m != "sknarx.testing")
    assert not users, users


def test_one_gap_core_and_front_ends_that_write_nothing():
    """Both measurement front ends rank, decide and bootstrap through the gap core and
    return a result; only the report modules write files."""
    gap = PKG / "gap"
    core_steps = {"rank", "decide", "preferred", "bootstrap_shrink", "log_shrink",
                  "alternating_split", "search", "conclude"}
    for path in gap.glob("*.py"):
        if path.name == "core.py":
            continue
        tree = ast.parse(path.read_text())
        defined = {n.name.lstrip("_") for n in ast.walk(tree)
                   if isinstance(n, ast.FunctionDef) and n.col_offset == 0}
        assert not defined & core_steps, f"{path.name} redefines {defined & core_steps}"
    for front in ("diagnosis.py", "orderdomain.py"):
        tree = ast.parse((gap / front).read_text())
        calls = {n.func.attr for n in ast.walk(tree)
                 if isinstance(n, ast.Call) and isinstance(n.func, ast.Attribute)}
        assert not calls & {"write_text", "to_csv", "savefig", "mkdir"}, front
        assert "sknarx.gap.core" in imports(gap / front)
        assert not imports(gap / front) & {"sknarx.gap.report", "sknarx.gap.bode_report"}


#: the calls that write a file
WRITERS = {"write_text", "write_bytes", "to_csv", "to_parquet", "savefig"}


def test_every_file_the_package_writes_is_written_whole_or_not_at_all():
    """A write call appears only inside the callback ``lambda tmp: ...`` handed to
    ``sknarx._atomic.write_atomic`` (which writes a temporary file and replaces the
    target in one step), so a run stopped mid-write never leaves a truncated model,
    report, sweep table or figure; ``open`` only reads."""
    offenders = []
    for path in PKG.rglob("*.py"):
        tree = ast.parse(path.read_text())
        in_callback = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.Lambda) and [a.arg for a in node.args.args] == ["tmp"]:
                in_callback.update(id(n) for n in ast.walk(node.body))
        for node in ast.walk(tree):
            if not isinstance(node, ast.Call) or id(node) in in_callback:
                continue
            f = node.func
            if isinstance(f, ast.Attribute) and f.attr in WRITERS:
                offenders.append(f"{path.name}:{node.lineno} .{f.attr}")
            if isinstance(f, ast.Name) and f.id == "open":
                modes = [a.value for a in node.args[1:2] if isinstance(a, ast.Constant)]
                modes += [k.value.value for k in node.keywords
                          if k.arg == "mode" and isinstance(k.value, ast.Constant)]
                if any(set(m) & set("wax+") for m in modes):
                    offenders.append(f"{path.name}:{node.lineno} open({modes[0]!r})")
    assert not offenders, offenders
