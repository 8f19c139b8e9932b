"""Every Python block in README.md and docs/*.md runs as written, warns nothing, and its
scores are finite and informative.

The blocks of one page run in order in one namespace (later blocks use what earlier
ones made), in a scratch folder. A block whose first line is ``# not run: <why>`` is
skipped (it needs something a test machine does not have, e.g. a dask cluster).
"""

import os
import re
import warnings
from pathlib import Path

import numpy as np
import pytest
from sklearn.model_selection import GridSearchCV

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
BLOCK = re.compile(r"```python\n(.*?)```", re.S)


def blocks(page):
    return [b for b in BLOCK.findall(page.read_text()) if not b.startswith("# not run")]


def check_scores(namespace):
    """Scores in the namespace are finite; a grid search's settings do not all tie."""
    for name, value in namespace.items():
        if isinstance(value, dict) and "test_score" in value:
            assert np.all(np.isfinite(value["test_score"])), name
        if isinstance(value, GridSearchCV):
            means = np.asarray(value.cv_results_["mean_test_score"], dtype=float)
            assert np.all(np.isfinite(means)), name
            assert np.unique(np.round(means, 12)).size == means.size, (
                f"{name}: settings score the same; the grid does not discriminate")


@pytest.mark.slow
@pytest.mark.parametrize("page", [p for p in PAGES if blocks(p)], ids=lambda p: p.name)
def test_documented_examples_run_without_warnings(page, tmp_path):
    namespace = {"__name__": "__docs__"}
    cwd = os.getcwd()
    os.chdir(tmp_path)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            for i, code in enumerate(blocks(page)):
                try:
                    exec(compile(code, f"{page.name}[block {i}]", "exec"), namespace)
                except Exception as exc:
                    raise AssertionError(f"{page.name}, block {i} failed: {exc!r}") from exc
    finally:
        os.chdir(cwd)
    check_scores(namespace)


def test_every_page_with_python_is_covered():
    covered = {p.name for p in PAGES if blocks(p)}
    assert {"README.md", "user_guide.md"} <= covered
