"""ament_python build of manipulator_kinematics (one package, one Python package per machine)."""

from glob import glob

from setuptools import find_packages, setup

PACKAGE = "manipulator_kinematics"

setup(
    name=PACKAGE,
    version="0.4.0",
    packages=find_packages(exclude=["test", "test.*", "benchmarks", "scripts"]),
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/config", glob("config/*.yaml")),
        (f"share/{PACKAGE}/urdf", glob("urdf/*.urdf")),
        (f"share/{PACKAGE}/launch", glob("launch/*.launch.xml")),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="manipulator_kinematics maintainers",
    maintainer_email="maintainers@manipulator-kinematics.org",
    description="Kinematics of hydraulic excavators and other manipulators, with rclpy nodes.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            # excavator (paper 000)
            "excavator_demo = excavator_kinematics.demo.demo:main",
            "excavator_forward = excavator_kinematics.nodes.forward_node:main",
            "excavator_velocity_ik = excavator_kinematics.nodes.velocity_ik_node:main",
            "excavator_sim = excavator_kinematics.nodes.sim_node:main",
            "excavator_ik_server = excavator_kinematics.nodes.ik_server_node:main",
            "excavator_imu_state = excavator_kinematics.nodes.imu_state_node:main",
            "excavator_slope_example = excavator_kinematics.demo.slope_example:main",
            # SCARA-type arm (paper 002)
            "scara_ik_server = scara_kinematics.nodes:ik_server",
            "scara_forward = scara_kinematics.nodes:forward",
            # pump-truck boom (paper 001)
            "pump_boom_forward = pump_boom_kinematics.nodes:forward",
            "pump_boom_ik_server = pump_boom_kinematics.nodes:ik_server",
            "pump_boom_regions = pump_boom_kinematics.build_regions:main",
            "pump_boom_plots = pump_boom_kinematics.plots:main",
            # tool changer (paper 003)
            "tool_changer_ik_server = tool_changer_kinematics.nodes:ik_server",
            "tool_changer_forward = tool_changer_kinematics.nodes:forward",
            "tool_changer_plots = tool_changer_kinematics.plots:main",
            # palletizer (paper 004)
            "palletizer_ik_server = palletizer_kinematics.nodes:ik_server",
            "palletizer_forward = palletizer_kinematics.nodes:forward",
            "palletizer_plots = palletizer_kinematics.plots:main",
            # the hydraulic family (wheel loader, knuckle crane, any machine file)
            "hydraulic_forward = manipulator_kinematics.nodes.hydraulic:forward",
            "hydraulic_velocity_ik = manipulator_kinematics.nodes.hydraulic:velocity_ik",
            "hydraulic_sim = manipulator_kinematics.nodes.hydraulic:sim",
            "hydraulic_ik_server = manipulator_kinematics.nodes.hydraulic:ik_server",
            # bag tools and shared displays
            "mk_record = manipulator_kinematics.bag.record:main",
            "mk_replay = manipulator_kinematics.bag.replay:main",
            "mk_evaluate = manipulator_kinematics.bag.evaluate:main",
            "mk_asbuilt = manipulator_kinematics.bag.asbuilt:main",
            "machine_markers = manipulator_kinematics.nodes.markers:main",
            "mk_urdf = manipulator_kinematics.urdf:main",
            "mk_machine_check = manipulator_kinematics.hydraulic.check:main",
            "mk_calibrate = manipulator_kinematics.hydraulic.measure_up:main",
            "excavator_working_ranges = excavator_kinematics.tools.working_ranges:main",
        ],
        # The machine registry (manipulator_kinematics.registry): one Machine per machine package.
        "manipulator_kinematics.machines": [
            "excavator = excavator_kinematics.machine:MACHINE",
            "scara = scara_kinematics.machine:MACHINE",
            "pump_boom = pump_boom_kinematics.machine:MACHINE",
            "tool_changer = tool_changer_kinematics.machine:MACHINE",
            # pump_boom, tool_changer, palletizer: added by their packages
            "palletizer = palletizer_kinematics.machine:MACHINE",
            # the hydraulic family: machine files, one shared record factory
            "wheel_loader = manipulator_kinematics.hydraulic.machine:WHEEL_LOADER",
            "knuckle_crane = manipulator_kinematics.hydraulic.machine:KNUCKLE_CRANE",
        ],
    },
)
