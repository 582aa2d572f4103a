"""The README's set-up, as a newcomer runs it: ``pip install .``, a first ``granchain`` run, then
``pip install -e ".[test]"`` in the same environment, then granchain used from anywhere.

A first run used to write Numba's cache and a stamp file into ``site-packages/granchain/``; pip does
not track such files, so the editable reinstall left that directory behind holding only them, and it
shadowed the editable install (``granchain --help`` failed with ``cannot import name '__version__'``).
An installed package may also be read-only. The kernels are now cached in a per-user cache directory.

Installing the dependencies from a registry in a test is slow and needs a network: the fresh virtual
environment sees the running environment's packages through a ``.pth`` file (not granchain itself),
and pip installs granchain alone (``--no-deps --no-build-isolation``) from a copy of the sources (an
in-tree build would write ``build/`` and ``*.egg-info`` into the working tree).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
import venv
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _readme_first_line() -> str:
    """The quickstart's imports and its first line (the one that builds a random decorated chain),
    verbatim from README.md."""
    text = (ROOT / "README.md").read_text()
    block = text.split("## Quickstart", 1)[1].split("```python", 1)[1].split("```", 1)[0]
    lines = []
    for line in block.strip().splitlines():
        lines.append(line)
        if "gc.random_decorated(" in line:
            return "\n".join(lines)
    raise AssertionError("README's quickstart no longer builds a random decorated chain first")


def _files(tree: Path) -> dict:
    """{relative path: (size, modification time)} of every file under ``tree``."""
    return {str(p.relative_to(tree)): (p.stat().st_size, p.stat().st_mtime_ns) for p in tree.rglob("*")
            if p.is_file()}


def _dependencies_view(where: Path) -> Path:
    """A directory of links to every package of the running environment except granchain (and the
    editable-install hooks), for the fresh environment's ``.pth`` file."""
    where.mkdir()
    seen = set()
    for key in ("purelib", "platlib"):
        site = Path(sysconfig.get_paths()[key])
        for entry in site.iterdir() if site.is_dir() else ():
            name = entry.name
            if name in seen or name.startswith(("granchain", "__editable__", "_granchain")) or name.endswith(".pth"):
                continue
            seen.add(name)
            (where / name).symlink_to(entry)
    return where


def _offline_build_backend() -> bool:
    """Whether pip can build granchain here without build isolation: setuptools >= 70.1 builds wheels
    itself, older ones need the ``wheel`` package (the test extra asks for setuptools >= 70.1)."""
    try:
        import setuptools
    except ImportError:
        return False
    if tuple(int(p) for p in setuptools.__version__.split(".")[:2] if p.isdigit()) >= (70, 1):
        return True
    try:
        import wheel  # noqa: F401
    except ImportError:
        return False
    return True


@pytest.mark.slow
@pytest.mark.skipif(sys.platform == "win32", reason="symbolic links and bin/ paths of a POSIX virtual environment")
@pytest.mark.skipif(not _offline_build_backend(), reason="building granchain offline needs setuptools >= 70.1 "
                                                         "(pip install -e '.[test]' installs it) or wheel")
def test_readme_setup_in_one_environment_then_granchain_from_anywhere(tmp_path):
    """Install, run a command, reinstall editable, use it from a directory outside the sources.

    After ``pip install .`` and a first ``granchain pulse`` (which compiles and caches a kernel), not
    one file under the installed package was added or changed, and the kernel's cache is in the
    per-user cache directory (the positive control: the run did cache something, elsewhere). With
    the installed tree read-only (for a non-root user, where a write would fail), a second run works
    and leaves it unchanged. After ``pip install -e .`` no ``site-packages/granchain`` is left, and
    from elsewhere ``granchain --help`` and the README quickstart's first line work on the editable
    sources."""
    src = tmp_path / "src"
    src.mkdir()
    shutil.copytree(ROOT / "granchain", src / "granchain", ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(ROOT / name, src / name)

    env_dir = tmp_path / "v"
    venv.create(env_dir, with_pip=False)  # pip and setuptools come from the running environment too
    py = env_dir / "bin" / "python"
    site = Path(subprocess.run([py, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                               capture_output=True, text=True, check=True).stdout.strip())
    (site / "zz_granchain_test_dependencies.pth").write_text(f"{_dependencies_view(tmp_path / 'deps')}\n")

    cache = tmp_path / "user-cache"
    env = {k: v for k, v in os.environ.items() if not k.startswith(("NUMBA_CACHE_DIR", "PYTHONPATH", "VIRTUAL_ENV"))}
    env.update(GRANCHAIN_CACHE=str(cache), PATH=f"{env_dir / 'bin'}{os.pathsep}{env.get('PATH', '')}",
               PIP_DISABLE_PIP_VERSION_CHECK="1", PIP_NO_INDEX="1")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()

    def run(*argv, cwd=elsewhere):
        proc = subprocess.run([str(a) for a in argv], cwd=cwd, env=env, capture_output=True, text=True, timeout=600)
        assert proc.returncode == 0, f"{argv}: exit {proc.returncode}\n{proc.stdout[-2000:]}\n{proc.stderr[-3000:]}"
        return proc

    run(py, "-m", "pip", "install", "--quiet", "--no-deps", "--no-build-isolation", src)
    installed = site / "granchain"
    assert (installed / "__init__.py").is_file()
    before = _files(installed)

    run(env_dir / "bin" / "granchain", "pulse", "--radii", "1,1")
    assert _files(installed) == before, "a granchain run wrote into the installed package"
    assert list(cache.glob("numba/granchain-kernels-*/**/*.nbi")), "the kernel was not cached in the user cache"

    for path in [installed, *installed.rglob("*")]:
        path.chmod(path.stat().st_mode & ~0o222)
    try:
        run(env_dir / "bin" / "granchain", "pulse", "--radii", "1,1")
        assert _files(installed) == before
    finally:
        for path in [installed, *installed.rglob("*")]:
            path.chmod(path.stat().st_mode | 0o200)

    run(py, "-m", "pip", "install", "--quiet", "--no-deps", "--no-build-isolation", "-e", src)
    assert not installed.exists(), f"left behind by the editable reinstall: {sorted(_files(installed))}"

    run(env_dir / "bin" / "granchain", "--help")
    out = run(py, "-c", _readme_first_line() + "\nprint(gc.__file__)")
    assert out.stdout.split()[-1] == str(src / "granchain" / "__init__.py"), out.stdout


def test_the_bundled_theory_reference_is_netcdf3_that_scipy_reads():
    """The measured reference of the theory figure (U[0.01, 0.4], N = 26) is a netCDF3 file (classic or
    64-bit offset: SciPy's reader, a base dependency, opens it; an HDF5-based netCDF4 file needs netCDF4
    or h5netcdf, which only the extras install), and it is what the figure reads: six finite,
    positive curves over the 26 large granules, with their standard errors."""
    import numpy as np
    import xarray as xr

    from granchain.paper.figures.theory import REFERENCE

    assert REFERENCE.read_bytes()[:4] in (b"CDF\x01", b"CDF\x02"), REFERENCE.read_bytes()[:8]
    with xr.open_dataset(REFERENCE, engine="scipy") as ds:
        assert list(ds["granule"].values) == list(range(1, 27))
        for name in ("mean_peak_velocity", "averaged_peak_velocity", "arrival_time_std"):
            for var in (name, f"{name}_stderr"):
                values = ds[var].values
                assert values.dtype == np.float64 and values.shape == (26,), var
                assert np.isfinite(values[1:]).all() and (values[1:] > 0).all(), var
        assert "realizations=3000" in ds.attrs["source"]


def test_the_theory_figure_reads_its_reference_without_netcdf4_or_h5netcdf(monkeypatch):
    """A base install (no netCDF4, no h5netcdf) gets the measured curves of the theory figure at the
    paper's point. The two packages are made unimportable here (``sys.modules[name] = None`` makes
    ``import name`` raise ImportError), so a reader that needed either fails this test; reading the
    HDF5 file the reference used to be fails too, with or without SciPy's engine named."""
    import numpy as np

    from granchain.model.distributions import Uniform
    from granchain.paper.figures import theory as figure

    for name in ("netCDF4", "h5netcdf", "h5py"):
        monkeypatch.setitem(sys.modules, name, None)
    measured = figure._measured(None, Uniform(0.01, 0.4), 26)
    assert measured is not None and "3000 realisations" in measured["source"]
    values, stderr = measured["averaged_peak_velocity"]
    assert values.shape == stderr.shape == (26,) and np.isfinite(values[1:]).all()
    assert figure._measured(None, Uniform(0.01, 0.3), 26) is None  # elsewhere there is no reference


def test_the_user_cache_directory_follows_the_environment(monkeypatch, tmp_path):
    """granchain's per-user cache directory (the compiled kernels, the theory's tables): $GRANCHAIN_CACHE,
    else ``granchain`` under $XDG_CACHE_HOME when that is an absolute path (the XDG convention: a relative
    one is ignored, it would depend on the working directory), else under ~/.cache. The theory's tables
    keep their place under it (``granchain.theory.cache_dir``)."""
    from granchain import theory
    from granchain._cache import user_cache_dir

    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    monkeypatch.delenv("GRANCHAIN_CACHE", raising=False)
    monkeypatch.delenv("XDG_CACHE_HOME", raising=False)
    assert user_cache_dir() == tmp_path / "home" / ".cache" / "granchain"
    monkeypatch.setenv("XDG_CACHE_HOME", "relative/cache")
    assert user_cache_dir() == tmp_path / "home" / ".cache" / "granchain"
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert user_cache_dir() == tmp_path / "xdg" / "granchain"
    monkeypatch.setenv("GRANCHAIN_CACHE", str(tmp_path / "own"))
    assert user_cache_dir() == tmp_path / "own"
    assert theory.cache_dir() == tmp_path / "own" / "theory"
    assert not (tmp_path / "own").exists()  # nothing is created by asking
