"""Packaging and quality checks: colcon build and ``ros2 run`` layout, the generated parameter
file, the rclpy-free core, lint, package.xml and setup.cfg."""

from __future__ import annotations

import configparser
import dataclasses
import importlib.util
import os
import shutil
import stat
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from endeff_ros.core.errors import ParameterError
from endeff_ros.core.params import EndeffParams, describe, load_yaml, to_ros_yaml

REPO = Path(__file__).resolve().parents[1]
PACKAGE = 'endeff_ros'
CONFIG = REPO / 'config' / 'endeff.yaml'
#: Paths of the checkout that never belong in a source workspace copy.
_IGNORED = shutil.ignore_patterns('.venv', 'build', 'install', 'log', 'data', '.git',
                                  '__pycache__', '*.egg-info', '.pytest_cache', '.ruff_cache',
                                  'bench*.json')


def _clean_env(**extra: str) -> dict[str, str]:
    """The test's environment without ROS workspace variables, plus ``extra``."""
    drop = ('AMENT_PREFIX_PATH', 'COLCON_PREFIX_PATH', 'PYTHONPATH', 'CMAKE_PREFIX_PATH')
    env = {k: v for k, v in os.environ.items() if k not in drop}
    env['PYTHONDONTWRITEBYTECODE'] = '1'
    env.update(extra)
    return env


def _colcon_command() -> list[str]:
    if importlib.util.find_spec('colcon_core') is not None:
        return [sys.executable, '-m', 'colcon']
    exe = shutil.which('colcon')
    if exe is None:
        pytest.skip('colcon is not installed (pip install colcon-common-extensions)')
    return [exe]


def _colcon_build(root: Path, *extra: str) -> Path:
    """Copy the checkout to ``root/src/endeff_ros``, colcon build it; returns the install dir."""
    src = root / 'src' / PACKAGE
    shutil.copytree(REPO, src, ignore=_IGNORED)
    cmd = [*_colcon_command(), 'build', '--packages-select', PACKAGE,
           '--base-paths', str(root / 'src'), *extra]
    proc = subprocess.run(cmd, cwd=root, env=_clean_env(COLCON_HOME=str(root / '.colcon')),
                          capture_output=True, text=True, timeout=300, check=False)
    logs = sorted((root / 'log').glob('latest_build/*/stdout_stderr.log'))
    detail = '\n'.join(p.read_text(errors='replace')[-4000:] for p in logs)
    assert proc.returncode == 0, (f'colcon build failed ({proc.returncode}):\n{proc.stdout}\n'
                                  f'{proc.stderr}\n{detail}')
    return root / 'install'


def _site_packages(prefix: Path) -> Path:
    found = sorted(prefix.glob('lib/python3*/site-packages'))
    assert found, f'no lib/python3*/site-packages under {prefix}'
    return found[0]


@pytest.fixture(scope='module')
def install(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _colcon_build(tmp_path_factory.mktemp('ws'))


def _ros2_run_prefix(install_dir: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """Resolve the package prefix exactly as ``ros2 run`` does (ament index lookup)."""
    ament_index_python = pytest.importorskip('ament_index_python')
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(install_dir / PACKAGE))
    return Path(ament_index_python.get_package_prefix(PACKAGE))


def _is_executable(path: Path) -> bool:
    return path.is_file() and os.access(path, os.X_OK) and bool(path.stat().st_mode & stat.S_IXUSR)


# --- colcon build ----------------------------------------------------------------------------

@pytest.mark.integration
def test_colcon_install_layout_matches_ros2_run(install: Path,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    prefix = _ros2_run_prefix(install, monkeypatch)
    assert prefix == install / PACKAGE
    for exe in ('endeff_node', 'endeff'):
        path = prefix / 'lib' / PACKAGE / exe
        assert _is_executable(path), f'{path} missing or not executable (ros2 run looks here)'
    share = prefix / 'share' / PACKAGE
    assert (prefix / 'share' / 'ament_index' / 'resource_index' / 'packages' / PACKAGE).is_file()
    assert (share / 'package.xml').read_bytes() == (REPO / 'package.xml').read_bytes()
    assert (share / 'config' / 'endeff.yaml').read_bytes() == CONFIG.read_bytes()
    # rviz:=true of the launch file opens the installed RViz2 configuration.
    assert (share / 'config' / 'endeff.rviz').read_bytes() == (
        REPO / 'config' / 'endeff.rviz').read_bytes()
    launch_src = sorted(p.name for p in (REPO / 'launch').glob('*.py'))
    launch_dst = sorted(p.name for p in (share / 'launch').glob('*.py'))
    assert launch_dst == launch_src, 'launch files missing from the install'
    site = _site_packages(prefix)
    assert (site / PACKAGE / 'core' / 'flow.py').is_file()
    # The published confidence's and kinds' models (package data, read at run time).
    for model in ('confidence_model.json', 'kind_model.json'):
        assert (site / PACKAGE / 'core' / model).read_bytes() == (
            REPO / PACKAGE / 'core' / model).read_bytes()
    assert not (site / 'test').exists(), 'the test directory must not be installed'
    assert not (site / 'tools').exists(), 'development tools must not be installed'
    tool_modules = {p.stem for p in (REPO / 'tools').glob('*.py')} - {'__init__'}
    installed = {p.stem for p in site.rglob('*.py')}
    assert not tool_modules & installed, f'tools installed: {sorted(tool_modules & installed)}'


@pytest.mark.integration
def test_installed_entry_points(install: Path) -> None:
    site = _site_packages(install / PACKAGE)
    eps = configparser.ConfigParser()
    eps.read(next(site.glob('endeff_ros-*-info/entry_points.txt')))
    scripts = dict(eps['console_scripts'])
    assert scripts['endeff_node'] == 'endeff_ros.ros.node:main'
    assert scripts['endeff'] == 'endeff_ros.cli:main'
    module = scripts['endeff_node'].split(':')[0]
    assert (site / (module.replace('.', '/') + '.py')).is_file()


@pytest.mark.integration
def test_installed_endeff_script_prints_the_config(install: Path) -> None:
    prefix = install / PACKAGE
    env = _clean_env(PYTHONPATH=str(_site_packages(prefix)), AMENT_PREFIX_PATH=str(prefix))
    # cwd outside the checkout, so nothing is imported from the source tree by accident.
    out = subprocess.run([str(prefix / 'lib' / PACKAGE / 'endeff'), 'params', '--yaml'],
                         cwd=prefix, env=env, capture_output=True, text=True, timeout=60,
                         check=False)
    assert out.returncode == 0, out.stderr
    assert out.stdout == CONFIG.read_text(encoding='utf-8')
    where = subprocess.run([sys.executable, '-c', 'import endeff_ros; print(endeff_ros.__file__)'],
                           cwd=prefix, env=env, capture_output=True, text=True, timeout=60,
                           check=True)
    assert Path(where.stdout.strip()).is_relative_to(prefix), 'import did not use the install'


@pytest.mark.integration
def test_colcon_symlink_install(tmp_path: Path) -> None:
    """``colcon build --symlink-install`` (setup.py develop with script_dir) also works."""
    from importlib.metadata import version

    if int(version('setuptools').split('.')[0]) >= 80:
        pytest.skip('setuptools >= 80 dropped `setup.py develop --editable`, which colcon '
                    'uses for --symlink-install (colcon/colcon-core#696)')
    install_dir = _colcon_build(tmp_path, '--symlink-install')
    prefix = install_dir / PACKAGE
    for exe in ('endeff_node', 'endeff'):
        assert _is_executable(prefix / 'lib' / PACKAGE / exe)
    assert (prefix / 'share' / PACKAGE / 'config' / 'endeff.yaml').resolve().read_bytes() \
        == CONFIG.read_bytes()
    bash = shutil.which('bash')
    if bash is None:
        return
    # As a user would: source the workspace, then run the script from the ament prefix.
    script = (f'source {install_dir / "local_setup.bash"} && '
              f'"$(dirname "$(echo $AMENT_PREFIX_PATH | cut -d: -f1)")/{PACKAGE}/lib/{PACKAGE}'
              f'/endeff" params --yaml')
    out = subprocess.run([bash, '-c', script], cwd=tmp_path, env=_clean_env(),
                         capture_output=True, text=True, timeout=60, check=False)
    assert out.returncode == 0, out.stderr
    assert out.stdout == CONFIG.read_text(encoding='utf-8')


# --- the parameter file ----------------------------------------------------------------------

def test_config_file_is_generated_from_the_dataclass() -> None:
    assert CONFIG.read_text(encoding='utf-8') == to_ros_yaml(), (
        'config/endeff.yaml is stale: regenerate it with `endeff params --yaml > '
        'config/endeff.yaml`')


def test_config_file_loads_to_the_defaults() -> None:
    assert load_yaml(str(CONFIG)) == EndeffParams()


def test_preset_files_are_generated_and_load() -> None:
    from endeff_ros.core.params import PRESETS

    for name, values in PRESETS.items():
        path = REPO / 'config' / f'endeff_{name}.yaml'
        params = EndeffParams(**values)
        assert path.read_text(encoding='utf-8') == to_ros_yaml(params), (
            f'{path.name} is stale: regenerate it with `endeff params --yaml --preset {name}`')
        assert load_yaml(str(path)) == params != EndeffParams()


def test_every_parameter_is_documented() -> None:
    rows = describe()
    assert [r['name'] for r in rows] == [f.name for f in dataclasses.fields(EndeffParams)]
    for row in rows:
        assert len(row['doc']) > 10 and row['doc'].endswith('.'), row['name']
        lo, hi = row['lo'], row['hi']
        if row['type'] in ('int', 'float'):
            assert lo is not None and hi is not None, f'{row["name"]} has no range'
            assert lo <= row['default'] <= hi, row['name']


def test_paper_symbols_are_present() -> None:
    symbols = {row['symbol'] for row in describe() if row['symbol']}
    assert symbols >= {'δ_L', 'η_L', 'λ', 'P', 'g', 'N', 'ε_a', 'ε_b', 'T', 'σ'}
    text = CONFIG.read_text(encoding='utf-8')
    for symbol in ('[δ_L]', '[η_L]', '[λ]', '[σ]'):
        assert symbol in text


@pytest.mark.parametrize('row', [r for r in describe() if r['type'] in ('int', 'float')],
                         ids=lambda r: r['name'])
def test_out_of_range_values_are_rejected(row: dict[str, object]) -> None:
    name, lo, hi = row['name'], row['lo'], row['hi']
    step = 1 if row['type'] == 'int' else 1e-6
    for bad in (lo - step, hi + step):  # type: ignore[operator]
        value = int(bad) if row['type'] == 'int' else float(bad)
        with pytest.raises(ParameterError, match=name):
            EndeffParams.from_dict({name: value})
        with pytest.raises(ParameterError, match=name):
            EndeffParams().replace(**{name: value})


def test_unknown_and_wrong_typed_values_are_rejected(tmp_path: Path) -> None:
    with pytest.raises(ParameterError, match='unknown parameter.*no_such_param'):
        EndeffParams.from_dict({'no_such_param': 1})
    with pytest.raises(ParameterError, match='band_eta must be int'):
        EndeffParams.from_dict({'band_eta': 4.5})
    with pytest.raises(ParameterError, match='band_delta must be float'):
        EndeffParams.from_dict({'band_delta': '0.07'})
    with pytest.raises(ParameterError, match='floor_removal must be bool'):
        EndeffParams.from_dict({'floor_removal': 1})
    with pytest.raises(ParameterError, match='keep_frames must be int'):
        EndeffParams.from_dict({'keep_frames': True})
    with pytest.raises(ParameterError, match='flow_method'):
        EndeffParams.from_dict({'flow_method': 'ldof'})
    with pytest.raises(ParameterError, match='box_min_x'):
        EndeffParams.from_dict({'box_min_x': 1.0, 'box_max_x': 0.5})
    path = tmp_path / 'bad.yaml'
    path.write_text('endeff_node:\n  ros__parameters:\n    band_delta: fast\n', encoding='utf-8')
    with pytest.raises(ParameterError, match='band_delta'):
        load_yaml(str(path))
    path.write_text('endeff_node:\n  ros__parameters:\n    typo_delta: 0.1\n', encoding='utf-8')
    with pytest.raises(ParameterError, match='typo_delta'):
        load_yaml(str(path))
    path.write_text('- 1\n- 2\n', encoding='utf-8')
    with pytest.raises(ParameterError, match='mapping'):
        load_yaml(str(path))
    # An int for a float parameter is fine (YAML writes 1 for 1.0).
    assert EndeffParams.from_dict({'band_delta': 1}).band_delta == 1.0


def test_constructor_rejects_wrong_types() -> None:
    with pytest.raises(ParameterError, match='band_eta'):
        EndeffParams(band_eta='4')  # type: ignore[arg-type]
    with pytest.raises(ParameterError, match='floor_removal'):
        EndeffParams().replace(floor_removal=1)
    assert EndeffParams(band_delta=1).band_delta == 1  # an int where a float is expected


# --- the algorithm core never imports ROS ----------------------------------------------------

def _module_names() -> list[str]:
    names = []
    for path in sorted((REPO / PACKAGE / 'core').glob('*.py')):
        names.append(f'{PACKAGE}.core' if path.stem == '__init__' else
                     f'{PACKAGE}.core.{path.stem}')
    for path in sorted((REPO / PACKAGE / 'synth').glob('*.py')):
        names.append(f'{PACKAGE}.synth' if path.stem == '__init__' else
                     f'{PACKAGE}.synth.{path.stem}')
    names += [f'{PACKAGE}.{m}' for m in ('synth', 'scoring', 'evaluate', 'bag.reader', 'sync',
                                         'cli', 'ros.scheduler', 'ros.processing')]
    return list(dict.fromkeys(names))


_NO_ROS = ('import importlib, sys\n'
           'importlib.import_module(sys.argv[1])\n'
           "bad = sorted(m for m in sys.modules if m.startswith(('rclpy', 'sensor_msgs', "
           "'visualization_msgs')))\n"
           'assert not bad, f"{sys.argv[1]} imports ROS: {bad[:5]}"\n')


@pytest.mark.parametrize('module', _module_names())
def test_module_does_not_import_ros(module: str) -> None:
    proc = subprocess.run([sys.executable, '-c', _NO_ROS, module], cwd=REPO,
                          env=_clean_env(PYTHONPATH=str(REPO)), capture_output=True, text=True,
                          timeout=120, check=False)
    assert proc.returncode == 0, proc.stderr[-3000:]


_NO_PIP_ONLY = ('import importlib, sys\n'
                'importlib.import_module(sys.argv[1])\n'
                "bad = sorted(m for m in sys.modules if m.split('.')[0] in "
                "('rosbags', 'mcap', 'mcap_ros2', 'matplotlib', 'colcon_core'))\n"
                'assert not bad, f"{sys.argv[1]} imports pip-only packages: {bad[:5]}"\n')


@pytest.mark.parametrize('module', ['endeff_ros.ros.node', 'endeff_ros.ros.convert',
                                    'endeff_ros.core.tracker'])
def test_node_needs_no_pip_only_package(module: str) -> None:
    """On a robot with apt-installed Jazzy the node runs without the PyPI-only tools."""
    proc = subprocess.run([sys.executable, '-c', _NO_PIP_ONLY, module], cwd=REPO,
                          env=_clean_env(PYTHONPATH=str(REPO)), capture_output=True, text=True,
                          timeout=120, check=False)
    assert proc.returncode == 0, proc.stderr[-3000:]


# --- lint, package.xml, setup.cfg --------------------------------------------------------------

def test_ruff_passes() -> None:
    if importlib.util.find_spec('ruff') is not None:
        cmd = [sys.executable, '-m', 'ruff']
    elif shutil.which('ruff'):
        cmd = [str(shutil.which('ruff'))]
    else:
        pytest.skip('ruff is not installed')
    proc = subprocess.run([*cmd, 'check', '--no-cache', '--output-format', 'concise',
                           'endeff_ros', 'test', 'tools'], cwd=REPO, capture_output=True,
                          text=True, timeout=120, check=False)
    files = sorted({line.split(':', 1)[0] for line in proc.stdout.splitlines()
                    if line.startswith(('endeff_ros', 'test', 'tools')) and ':' in line})
    assert proc.returncode == 0, (f'ruff fails in {len(files)} file(s): {", ".join(files)}\n'
                                  f'{proc.stdout}{proc.stderr}')


def test_package_xml() -> None:
    root = ET.parse(REPO / 'package.xml').getroot()
    assert root.tag == 'package' and root.get('format') == '3'
    assert root.findtext('name') == PACKAGE
    deps = {e.text for e in root if e.tag in ('depend', 'exec_depend', 'build_depend')}
    required = {'rclpy', 'sensor_msgs', 'visualization_msgs', 'std_msgs', 'python3-numpy',
                'python3-scipy', 'python3-opencv', 'python3-rosbags-pip'}
    assert required <= deps, f'missing dependency keys: {sorted(required - deps)}'
    assert root.find('export/build_type') is not None
    assert root.findtext('export/build_type') == 'ament_python'
    for tag in ('description', 'maintainer', 'license'):
        assert (root.findtext(tag) or '').strip(), f'package.xml lacks <{tag}>'


#: rosdep key of each imported distribution whose key is not its module name (ROS packages'
#: keys are their names). rosbags and mcap have no Debian package: pip keys (rosdistro's
#: rosdep/python.yaml has no key for mcap itself; mcap-ros2-support installs it, and mcap
#: brings zstandard).
ROSDEP_KEYS = {'cv2': 'python3-opencv', 'numpy': 'python3-numpy', 'scipy': 'python3-scipy',
               'yaml': 'python3-yaml', 'matplotlib': 'python3-matplotlib',
               'tqdm': 'python3-tqdm', 'numba': 'python3-numba', 'rosbags': 'python3-rosbags-pip',
               'mcap': 'mcap-ros2-support', 'zstandard': 'mcap-ros2-support'}
#: Imported but deliberately not declared, and why.
NOT_DECLARED = {
    'pybullet_data': 'only the default --from of `endeff mocap-fetch deepmimic` (a data '
                     'fetch); without pybullet the command asks for --from',
}


def _third_party_imports(paths: list[Path]) -> dict[str, str]:
    """Top-level modules imported by ``paths`` outside the standard library and the package,
    each with one file importing it."""
    import ast

    found: dict[str, str] = {}
    for path in paths:
        for node in ast.walk(ast.parse(path.read_text(encoding='utf-8'))):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            else:
                continue
            for name in names:
                top = name.split('.')[0]
                if top not in sys.stdlib_module_names and top != PACKAGE:
                    found.setdefault(top, str(path.relative_to(REPO)))
    return found


def test_every_runtime_import_is_declared_in_package_xml() -> None:
    """rosdep installs what package.xml declares, nothing else: an import without its key
    breaks the package on a robot (mcap, imported by bag/salvage.py, was missing)."""
    root = ET.parse(REPO / 'package.xml').getroot()
    declared = {e.text for e in root if e.tag in ('depend', 'exec_depend')}
    paths = sorted((REPO / PACKAGE).rglob('*.py')) + sorted((REPO / 'launch').glob('*.py'))
    imports = _third_party_imports(paths)
    assert {'rclpy', 'numpy', 'mcap', 'rosbags'} <= set(imports)  # the scan sees imports
    missing = {f'{ROSDEP_KEYS.get(m, m)} (import {m} in {where})'
               for m, where in imports.items()
               if m not in NOT_DECLARED and ROSDEP_KEYS.get(m, m) not in declared}
    assert not missing, f'package.xml lacks: {sorted(missing)}'
    stale = set(NOT_DECLARED) - set(imports)
    assert not stale, f'NOT_DECLARED lists modules no longer imported: {sorted(stale)}'


def test_package_version_matches_setup() -> None:
    import endeff_ros

    root = ET.parse(REPO / 'package.xml').getroot()
    assert root.findtext('version') == endeff_ros.__version__
    assert f"version='{endeff_ros.__version__}'" in (REPO / 'setup.py').read_text()


def test_setup_cfg_puts_scripts_in_lib_package() -> None:
    cfg = configparser.ConfigParser()
    cfg.read(REPO / 'setup.cfg')
    # Underscore keys: setuptools deprecates (and newer versions reject) 'script-dir'.
    assert cfg.get('develop', 'script_dir') == f'$base/lib/{PACKAGE}'
    assert cfg.get('install', 'install_scripts') == f'$base/lib/{PACKAGE}'
    assert (REPO / 'resource' / PACKAGE).is_file(), 'ament resource marker missing'
