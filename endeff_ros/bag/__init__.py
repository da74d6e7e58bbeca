"""Offline rosbag2 tools: reading benchmark bags, ``endeff process``, throughput benchmark.

- ``reader``         open a bag (sqlite3 or mcap), pick topics, synchronise, yield frames
- ``process``        ``endeff process``: run the tracker on bags, write result bags
- ``bench_process``  frames/s of ``endeff process`` on one core and on N processes
- ``errors``         :class:`~endeff_ros.bag.errors.BagError`, the one error of this package
"""
