"""endeff_ros: time-consistent end-effector estimation from RGB-D data (Lin et al., 2016)."""

__version__ = '0.1.0'
