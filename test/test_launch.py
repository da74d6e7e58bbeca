"""The launch file cannot run here (no `launch` on PyPI): it parses and its references exist."""

from __future__ import annotations

import ast
import importlib.util
import sys
import types
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LAUNCH = ROOT / 'launch' / 'endeff.launch.py'


def _tree() -> ast.Module:
    return ast.parse(LAUNCH.read_text(encoding='utf-8'), filename=str(LAUNCH))


def _strings(tree: ast.Module) -> set[str]:
    return {n.value for n in ast.walk(tree) if isinstance(n, ast.Constant) and
            isinstance(n.value, str)}


def test_parses_and_defines_generate_launch_description():
    names = {n.name for n in _tree().body if isinstance(n, ast.FunctionDef)}
    assert 'generate_launch_description' in names


def test_referenced_files_exist_and_are_installed():
    strings = _strings(_tree())
    for name in ('endeff.yaml', 'fastdds_shm.xml'):
        assert name in strings
        assert (ROOT / 'config' / name).is_file()
    setup = (ROOT / 'setup.py').read_text(encoding='utf-8')
    assert "glob('config/*.yaml')" in setup and "glob('config/*.xml')" in setup
    assert "glob('launch/*.py')" in setup


def test_references_the_node_executable_and_its_inputs():
    strings = _strings(_tree())
    assert {'endeff_ros', 'endeff_node', 'camera', 'FASTDDS_DEFAULT_PROFILES_FILE'} <= strings
    assert {'color/image_raw', 'depth/image_raw', 'depth/camera_info'} <= strings
    setup = (ROOT / 'setup.py').read_text(encoding='utf-8')
    assert 'endeff_node = endeff_ros.ros.node:main' in setup


def test_reads_the_packaged_parameter_file(monkeypatch):
    """Import the launch file against stub ``launch`` modules; its yaml reader works."""
    for name in ('launch', 'launch.actions', 'launch.conditions', 'launch.substitutions',
                 'launch_ros',
                 'launch_ros.actions', 'launch_ros.parameter_descriptions',
                 'ament_index_python', 'ament_index_python.packages'):
        if name not in sys.modules or name.startswith('launch'):
            stub = types.ModuleType(name)
            stub.__getattr__ = lambda attr: object  # type: ignore[attr-defined]
            monkeypatch.setitem(sys.modules, name, stub)
    spec = importlib.util.spec_from_file_location('endeff_launch', LAUNCH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    params = module._node_parameters(str(ROOT / 'config' / 'endeff.yaml'))
    from endeff_ros.core.params import EndeffParams

    assert set(params) == set(EndeffParams().to_dict())


def test_rviz_config_shows_the_outputs_and_is_installed():
    """``rviz:=true`` opens config/endeff.rviz, which colcon installs (setup.py) and which
    shows the node's outputs under the launch file's default namespace: the markers with
    their labels, the end-effector cloud coloured by its ``kind`` field, the bands, and the
    depth image as a cloud."""
    import yaml

    strings = _strings(_tree())
    assert {'rviz', 'rviz2', 'endeff.rviz'} <= strings
    setup = (ROOT / 'setup.py').read_text(encoding='utf-8')
    assert "glob('config/*.rviz')" in setup
    config = yaml.safe_load((ROOT / 'config' / 'endeff.rviz').read_text(encoding='utf-8'))
    displays = {d['Class']: d for d in config['Visualization Manager']['Displays']
                if d.get('Enabled')}
    markers = displays['rviz_default_plugins/MarkerArray']
    assert markers['Topic']['Value'] == '/camera/end_effectors/markers'
    assert markers['Namespaces']['labels'] is True
    clouds = {d['Topic']['Value']: d for d in config['Visualization Manager']['Displays']
              if d['Class'] == 'rviz_default_plugins/PointCloud2'}
    assert clouds['/camera/end_effectors']['Channel Name'] == 'kind'
    assert clouds['/camera/debug/bands']['Color Transformer'] == 'RGB8'
    depth = displays['rviz_default_plugins/DepthCloud']
    assert depth['Depth Map Topic'] == '/camera/depth/image_raw'
    from endeff_ros.ros import convert

    assert 'kind' in convert.ENDEFF_DTYPE.names
