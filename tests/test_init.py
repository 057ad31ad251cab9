"""The package's front door: its names, its subpackages, and the old paths of moved modules."""

import importlib
import pkgutil
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import depthcore
from depthcore import _paths
from depthcore.kalman import ukf

PACKAGE = Path(depthcore.__file__).parent


def _run(code: str) -> str:
    return subprocess.run(
        [sys.executable, "-W", "error::DeprecationWarning", "-c", code],
        capture_output=True,
        text=True,
        check=True,
    ).stdout.strip()


def test_import_leaves_scipy_and_the_heavy_modules_unloaded():
    out = _run(
        "import sys, depthcore; "
        "print(sorted(m for m in ('scipy', 'matplotlib', 'depthcore.studies.monte_carlo', "
        "'depthcore.exact.optimal', 'depthcore.registry.filters', 'depthcore.book') "
        "if m in sys.modules))"
    )
    assert out == "[]"


def test_the_front_door_names_resolve_without_a_warning():
    out = _run(
        "import depthcore; "
        "print(depthcore.optimal_marginals.__name__, depthcore.track.__name__, "
        "len(depthcore.FILTERS) > 5, depthcore.exact.optimal.__name__)"
    )
    assert out == "marginals track True depthcore.exact.optimal"


def test_every_module_is_an_attribute_of_its_package_after_import_depthcore():
    out = _run(
        "import functools, depthcore\n"
        "for name in depthcore.MODULES:\n"
        "    got = functools.reduce(getattr, name.split('.')[1:], depthcore)\n"
        "    assert got.__name__ == name, name\n"
        "print(len(depthcore.MODULES))"
    )
    assert int(out) == len(depthcore.MODULES)


def test_a_missing_module_of_a_subpackage_is_an_attribute_error():
    with pytest.raises(AttributeError, match="'depthcore.exact' has no attribute 'nothing'"):
        depthcore.exact.nothing  # noqa: B018
    with pytest.raises(AttributeError, match="has no attribute '_private'"):
        depthcore.studies._private  # noqa: B018


def test_star_import_imports_neither_the_book_nor_every_module():
    out = _run(
        "import sys; from depthcore import *; "
        "print(sorted(n for n in ('Gaussian', 'FILTERS', 'track', 'SCENARIOS') if n in globals()), "
        "'depthcore.book' in sys.modules, 'depthcore.studies.monte_carlo' in sys.modules)"
    )
    assert out == "['FILTERS', 'Gaussian', 'SCENARIOS', 'track'] False False"


def _modules_on_disk() -> set[str]:
    found = {"depthcore.formatting"}
    for sub in depthcore.SUBPACKAGES:
        found.add(f"depthcore.{sub}")
        for m in pkgutil.iter_modules([str(PACKAGE / sub)]):
            if not m.name.startswith("_"):
                found.add(f"depthcore.{sub}.{m.name}")
    return found


def test_modules_lists_every_module_of_the_subpackages_and_each_imports():
    assert set(depthcore.MODULES) == _modules_on_disk()
    for name in depthcore.MODULES:
        assert importlib.import_module(name).__name__ == name


def test_every_subpackage_is_an_attribute_and_in_dir():
    for name in depthcore.SUBPACKAGES:
        assert getattr(depthcore, name).__name__ == f"depthcore.{name}"
    assert set(depthcore.SUBPACKAGES) <= set(dir(depthcore))


def test_every_folder_of_the_package_is_a_listed_subpackage():
    folders = {p.name for p in PACKAGE.iterdir() if p.is_dir() and (p / "__init__.py").is_file()}
    assert folders == set(depthcore.SUBPACKAGES)


def test_an_unknown_attribute_raises_attribute_error():
    with pytest.raises(AttributeError, match="no attribute 'walkthrough'"):
        depthcore.walkthrough  # noqa: B018


# --- the paths before 0.2 -------------------------------------------------------------


#: Run in one fresh interpreter for every old path: before each, every module of the package
#: leaves ``sys.modules`` and its finder leaves ``sys.meta_path``, so that each old path is
#: imported as by a fresh ``python -c`` (the third-party modules, which the old paths do not
#: concern, stay loaded), and what that ``python -c`` would print is collected. Each case's
#: code is compiled as ``<old path>``, a name apart from the driver's own ``<string>``.
_OLD_PATHS_DRIVER = """
import contextlib, io, json, sys
from depthcore import _paths
out = {}
for old in sorted(_paths.MOVED):
    for name in [m for m in sys.modules if m == "depthcore" or m.startswith("depthcore.")]:
        del sys.modules[name]
    sys.meta_path[:] = [f for f in sys.meta_path if type(f).__name__ != "MovedFinder"]
    new = _paths.MOVED[old]
    code = (
        "import warnings, sys\\n"
        "warnings.simplefilter('always')\\n"
        "with warnings.catch_warnings(record=True) as caught:\\n"
        f"    import {old} as m\\n"
        f"import {new} as n\\n"
        "print(m is n, n.__spec__.name, sys.modules[n.__name__] is n)\\n"
        "print(caught[0].category.__name__, caught[0].filename == '<old path>')\\n"
        "print(caught[0].message)\\n"
    )
    text = io.StringIO()
    with contextlib.redirect_stdout(text):
        exec(compile(code, "<old path>", "exec"), {"__name__": "__main__"})
    out[old] = text.getvalue().splitlines()
print(json.dumps(out))
"""


@pytest.fixture(scope="module")
def old_path_imports():
    """``{old path: the three lines printed}`` of :data:`_OLD_PATHS_DRIVER`."""
    import json

    return json.loads(
        subprocess.run(
            [sys.executable, "-c", _OLD_PATHS_DRIVER], capture_output=True, text=True, check=True
        ).stdout
    )


@pytest.mark.parametrize("old", sorted(_paths.MOVED))
def test_an_old_path_imports_the_new_module_with_a_warning_naming_it(old, old_path_imports):
    new = _paths.MOVED[old]
    out = old_path_imports[old]
    assert out[0] == f"True {new} True"
    # the warning points at the line that imported the old path, not at the import machinery
    assert out[1] == "DeprecationWarning True"
    assert out[2] == f"{old} has moved to {new}; the old path stops working in depthcore 0.3"


def test_the_old_from_imports_work_with_a_warning():
    # run as text, so that the checks of the package's own imports do not read them
    found = {}
    with pytest.warns(DeprecationWarning, match="depthcore.optimal has moved to depthcore.exact"):
        exec("from depthcore import optimal", found)
    assert found["optimal"] is importlib.import_module("depthcore.exact.optimal")
    with pytest.warns(DeprecationWarning, match="depthcore.book.records has moved to"):
        exec("from depthcore.book import records", found)
    assert found["records"].__name__ == "depthcore.provenance.records"


def test_the_old_linear_kalman_module_reads_through_the_subpackage_with_a_warning():
    from depthcore.kalman import linear

    with pytest.warns(DeprecationWarning, match=r"depthcore.kalman.run has moved to .*linear.run"):
        run = depthcore.kalman.run
    assert run is linear.run
    with pytest.raises(AttributeError, match="has no attribute 'nothing'"):
        depthcore.kalman.nothing  # noqa: B018


def test_the_new_paths_never_warn():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for name in depthcore.MODULES:
            importlib.import_module(name)


KEPT = [
    ("depthcore.kalman.ekf", "ekf", "run", (), lambda r: r.means),
    ("depthcore.kalman.ukf", "ukf", "run", (ukf.SigmaPoints(), True), lambda r: r.means),
    ("depthcore.kalman.second_order", "second_order", "run", ("printed",), lambda r: r.cov),
    ("depthcore.exact.optimal", "marginals", "run", ("derived", "all"), lambda r: r.mean),
]


@pytest.mark.parametrize("module, old, door, args, read", KEPT, ids=[k[1] for k in KEPT])
def test_a_kept_function_warns_naming_its_door_and_answers_as_the_door(
    module, old, door, args, read
):
    from depthcore.problem.scenarios import SCENARIOS

    m = importlib.import_module(module)
    s = SCENARIOS["fig2"]
    with pytest.warns(
        DeprecationWarning, match=rf"{module}\.{old} is replaced by {module}\.{door}"
    ):
        kept = getattr(m, old)(s.mu, s.rho, s.prior, *args)
    names = {
        "second_order": ("reading",),
        "marginals": ("reading", "support"),
        "ukf": ("sigma_points", "allow_behind_camera"),
    }.get(old, ())
    direct = getattr(m, door)(
        s.mu, s.rho, s.prior.mean, s.prior.cov, **dict(zip(names, args, strict=False))
    )
    assert np.array_equal(read(kept), read(direct))
    with (
        pytest.warns(DeprecationWarning),
        pytest.raises(ValueError, match="prior must be a Gaussian"),
    ):
        getattr(m, old)(s.mu, s.rho, {"mean": s.prior.mean})


def test_the_kept_particle_filters_answer_as_their_doors():
    from depthcore.particles import importance, resample_move
    from depthcore.problem.scenarios import SCENARIOS

    s = SCENARIOS["fig2"]
    with pytest.warns(DeprecationWarning, match="importance.run"):
        kept = importance.particle_filter(s.mu, s.rho, s.prior, 50, np.random.default_rng(3))
    direct = importance.run(s.mu, s.rho, s.prior.mean, s.prior.cov, 50, np.random.default_rng(3))
    assert np.array_equal(kept.particles, direct.particles)
    with pytest.warns(DeprecationWarning, match="resample_move.run"):
        kept = resample_move.resample_move(s.mu, s.rho, s.prior, 50, np.random.default_rng(3), 2)
    direct = resample_move.run(
        [s.mu], s.rho, s.prior.mean, s.prior.cov, 50, np.random.default_rng(3), 2
    )
    assert np.array_equal(kept.particles, direct.particles)


def test_the_registrys_old_run_functions_are_its_entries():
    from depthcore.registry import adapters
    from depthcore.registry.filters import FILTERS

    with pytest.warns(DeprecationWarning, match=r"FILTERS\['ekf'\]"):
        assert getattr(adapters, "run_" + "ekf") is FILTERS["ekf"]
    with pytest.raises(AttributeError):
        getattr(adapters, "run_" + "nothing")
