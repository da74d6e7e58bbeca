"""Offline rosbag2 tools: reading benchmark bags and recordings, ``endeff process``.

- ``reader``    open a bag (sqlite3 or mcap), pick raw or compressed topics, synchronise,
                yield frames
- ``salvage``   read a bag whose index is gone (a file cut short) message by message
- ``process``   ``endeff process``: run the tracker on bags, write result bags
- ``outputs``   output paths checked before any work, written aside, never clobbered
- ``progress``  optional tqdm progress bar, shared frame counter for worker processes
- ``errors``    :class:`~endeff_ros.bag.errors.BagError`, the one error of this package
"""
