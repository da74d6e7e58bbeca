"""Development tools of endeff_ros: benchmarks, the DDS demo, replay driver and relay.

Run from a source checkout (``python -m tools.NAME``); they are not installed by colcon or pip,
so a robot's install holds only the node, the core and the offline bag tools.
"""
