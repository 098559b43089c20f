"""Install: compatible ranges in pyproject.toml (installable beside other packages), exact pins in the lock
files that setup, CI and the image install from, and the lock covering every declared requirement."""

from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

from packaging.requirements import Requirement

ROOT = Path(__file__).resolve().parents[2]


def test_dependencies_are_compatible_ranges():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    extras = project["optional-dependencies"]
    assert set(extras) == {"service", "dev"}
    for text in project["dependencies"] + extras["service"] + extras["dev"]:
        if Requirement(text).name == "pdeanim":  # an extra naming another one: pdeanim[service]
            continue
        specs = Requirement(text).specifier
        assert not any(s.operator in ("==", "===") for s in specs), f"{text}: pin it in the lock, not here"
        assert any(s.operator == ">=" for s in specs) and any(s.operator == "<" for s in specs), \
            f"{text}: give a lower bound and an upper bound before the next breaking version"


def test_lock_files_cover_pyproject():
    proc = subprocess.run([sys.executable, str(ROOT / "script" / "lockfile.py"), "check"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    runtime = (ROOT / "requirements.lock").read_text()
    assert "numpy==" in runtime and "pytest==" not in runtime  # the image gets no test tools
    assert "fastapi==" not in runtime and "sqlalchemy==" not in runtime  # the library installs alone
    service = (ROOT / "requirements-service.lock").read_text()
    assert service.splitlines()[2] == "-r requirements.lock" and "fastapi==" in service
    assert "pytest==" not in service
    assert (ROOT / "requirements-dev.lock").read_text().splitlines()[2] == "-r requirements-service.lock"


def test_setup_and_image_install_from_the_lock():
    setup = (ROOT / "script" / "setup").read_text()
    assert "-r requirements-dev.lock" in setup and "-e . --no-deps" in setup
    assert "command -v npm" in setup  # no Node: setup (and so script/demo) still works, without the validator
    assert "pip install -r requirements-service.lock" in (ROOT / "Dockerfile").read_text()


# A fresh interpreter in which the service extra's modules cannot be imported (as after pip install pdeanim).
WITHOUT_SERVICE_EXTRA = """
import importlib.abc, sys

class Refuse(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in {blocked!r}:
            raise ModuleNotFoundError(f"No module named {{name!r}}", name=name)
        return None

sys.meta_path.insert(0, Refuse())
"""


def _without_service_extra(code: str, *argv: str) -> subprocess.CompletedProcess:
    from pdeanim_service.cli import EXTRA_MODULES

    prelude = WITHOUT_SERVICE_EXTRA.format(blocked=sorted(EXTRA_MODULES))
    return subprocess.run([sys.executable, "-c", prelude + code, *argv], cwd=ROOT, capture_output=True,
                          text=True, timeout=300)


def test_the_library_and_its_commands_need_no_service_extra(tmp_path):
    """Every pdeanim module imports, and `pdeanim frame` runs, without FastAPI, SQLAlchemy, psycopg, boto3,
    uvicorn, pydantic or httpx: the core dependencies are the library's."""
    code = ("import pkgutil, importlib, pdeanim\n"
            "for m in pkgutil.walk_packages(pdeanim.__path__, 'pdeanim.'): importlib.import_module(m.name)\n"
            "from pdeanim_service.cli import main\n"
            "sys.exit(main(sys.argv[1:]))\n")
    clip = ROOT / "clients" / "js" / "test" / "fixtures" / "fit-displacement-chord.clip"
    out = _without_service_extra(code, "frame", str(clip), "--t", "0.5", "--out", str(tmp_path / "f.npz"))
    assert out.returncode == 0, out.stderr
    assert (tmp_path / "f.npz").stat().st_size > 0


def test_a_service_command_without_the_extra_names_it():
    out = _without_service_extra("from pdeanim_service.cli import main\nsys.exit(main(sys.argv[1:]))\n",
                                 "keys", "list")
    assert out.returncode == 2, out.stderr
    assert "needs the 'service' extra" in out.stderr and "pip install 'pdeanim[service]'" in out.stderr
    assert "Traceback" not in out.stderr


def test_a_wheel_installs_only_names_of_the_project(tmp_path):
    """What pip installs is named after the project (service/ and worker/ become pdeanim_service and
    pdeanim_worker), the viewer's static files come along as package data, and the build warns about
    nothing."""
    import zipfile

    build = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
                            "-w", str(tmp_path), str(ROOT)], capture_output=True, text=True, timeout=600)
    assert build.returncode == 0, build.stderr
    assert "warning" not in (build.stdout + build.stderr).lower(), build.stdout + build.stderr
    (wheel,) = tmp_path.glob("pdeanim-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    top = {name.split("/")[0] for name in names}
    packages = {t for t in top if not t.endswith(".dist-info")}
    assert packages == {"pdeanim", "pdeanim_service", "pdeanim_worker"}
    assert "pdeanim_service/api/static/viewer/index.html" in names
    assert any(n.startswith("pdeanim_service/store/migrations/versions/") for n in names)
