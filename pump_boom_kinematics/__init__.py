"""Concrete pump-truck boom (paper 001): plane geometry, region-planning IK, straight-line pours.

numpy core (no rclpy): :mod:`.kinematics` (the boom), :mod:`.regions` (the region table and its
builder), :mod:`.pour` (straight-line pours and paths), :mod:`.plots` (the paper's figures).
"""
