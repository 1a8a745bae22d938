"""The excavator's math (paper 000): numpy, scipy and numba only, no rclpy and no message package.

It imports nothing of the package outside ``core`` (test/test_layering.py checks both).
"""
