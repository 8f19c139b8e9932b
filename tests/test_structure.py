"""The package's layout rules: imports flow one way, nobody inside imports the root,
no module imports another that imports it back."""

import ast
import re
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
    """Both measurement front ends search, rank, decide and state the verdict through
    the one core (search, rule, evidence, document) and return a result; only the
    report modules write files."""
    gap = PKG / "gap"
    core = {"search.py": {"rank", "search"}, "rule.py": {"decide", "preferred"},
            "evidence.py": {"bootstrap_shrink", "log_shrink", "alternating_split"},
            "document.py": {"verdict_entries"}}
    steps = set().union(*core.values())
    for path in gap.glob("*.py"):
        tree = ast.parse(path.read_text())
        defined = {n.name.lstrip("_") for n in ast.walk(tree)
                   if isinstance(n, ast.FunctionDef)} - core.get(path.name, set())
        assert not defined & steps, f"{path.name} redefines {defined & steps}"
    for front in (gap / "timeseries.py", PKG / "bode" / "diagnosis.py"):
        tree = ast.parse(front.read_text())
        calls = {n.func.attr for n in ast.walk(tree)
                 if isinstance(n, ast.Call) and isinstance(n.func, ast.Attribute)}
        assert not calls & {"write_text", "to_csv", "savefig", "mkdir"}, front
        assert {"sknarx.gap.search", "sknarx.gap.document"} <= imports(front)
        assert not imports(front) & {"sknarx.gap.report", "sknarx.bode.report"}


def test_the_gap_package_is_rooms_a_newcomer_can_read():
    """One concept a module: none in gap/ over 600 lines, gap/ under 5,000 in all."""
    sizes = {p.name: len(p.read_text().splitlines()) for p in (PKG / "gap").glob("*.py")}
    assert max(sizes.values()) <= 600, sizes
    assert sum(sizes.values()) < 5000, sum(sizes.values())


#: what run history looks like in a comment or docstring: a date, a benchmark or record
#: path, a validation plant by name, a logged trial's seed or run, a commit
HISTORY = re.compile(r"\b20\d\d-\d\d-\d\d\b|benchmarks/|gap_validation|second plant|"
                     r"ROSS plant|independent plant|\bseeds? \d{4,}|\btrials? \d{4,}|"
                     r"\b\d{5} run\b|\bcommit [0-9a-f]{7}|\b(?:since|until|on) [0-9a-f]{7}\b")


def test_library_code_says_what_and_why_not_its_history():
    # (the shipped datasets' provenance names its sources' commits: that is the point)
    offenders = [f"{p.relative_to(PKG.parent)}:{i}: {line.strip()}"
                 for p in PKG.rglob("*.py") if p.parent.name != "datasets"
                 for i, line in enumerate(p.read_text().splitlines(), 1)
                 if HISTORY.search(line)]
    assert not offenders, "\n".join(offenders)


def test_the_command_line_sets_no_environment_when_imported():
    """Thread limits are the command's, set in ``main()``: importing the CLI (as a test
    or an application does) leaves the process's environment alone."""
    tree = ast.parse((PKG / "cli.py").read_text())
    top = [n for n in tree.body if not isinstance(n, (ast.FunctionDef, ast.ClassDef))]
    assert not any("environ" in ast.unparse(n) for n in top)


def test_warnings_are_caught_by_kind_not_silenced_wholesale():
    offenders = [f"{p.relative_to(PKG.parent)}:{i}"
                 for p in PKG.rglob("*.py")
                 for i, line in enumerate(p.read_text().splitlines(), 1)
                 if re.search(r"simplefilter\(\s*[\"']ignore[\"']\s*\)", line)]
    assert not offenders, offenders


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


def test_what_a_user_reads_points_at_shipped_data_not_the_projects_shared_folder():
    """A clone or an installed package has no ``../shared``: README, docs and examples
    name the shipped files (``sknarx datasets path NAME``, ``sknarx.datasets``)."""
    root = PKG.parent
    pages = [root / "README.md", *(root / "docs").glob("*.md"),
             *(root / "examples").rglob("*.py")]
    offenders = [str(p.relative_to(root)) for p in pages if "../shared" in p.read_text()]
    assert not offenders, offenders
