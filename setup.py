"""ament_python build of manipulator_kinematics (one package, one Python package per machine)."""
from glob import glob

from setuptools import find_packages, setup

PACKAGE = "manipulator_kinematics"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*", "benchmarks", "scripts"]),
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/config", glob("config/*.yaml")),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="manipulator_kinematics maintainers",
    maintainer_email="maintainers@manipulator-kinematics.org",
    description="Kinematics of hydraulic excavators and other manipulators, with rclpy nodes.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "excavator_demo = excavator_kinematics.demo:main",
            "excavator_forward = excavator_kinematics.forward_node:main",
            "excavator_velocity_ik = excavator_kinematics.velocity_ik_node:main",
            "excavator_sim = excavator_kinematics.sim_node:main",
            "scara_ik_server = scara_kinematics.ik_server:main",
            "scara_forward = scara_kinematics.forward_node:main",
            "record = manipulator_kinematics.bag.record:main",
            "replay = manipulator_kinematics.bag.replay:main",
            "evaluate = manipulator_kinematics.bag.evaluate:main",
        ],
    },
)
