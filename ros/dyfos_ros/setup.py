"""dyfos_ros: an ament_python package (colcon on a ROS 2 install) that pip also
installs into a venv of ROS 2 wheels (ros/install.sh)."""

from setuptools import setup

package_name = "dyfos_ros"

setup(
    name=package_name,
    version="0.1.0",
    packages=[package_name],
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
    ],
    # rclpy, the messages and `dyfos` come from ROS (package.xml) and ros/install.sh.
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="dyfos",
    maintainer_email="dyfos@example.invalid",
    description="The dyfos ROS 2 node over the dyfos Python binding",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            # `ros2 run dyfos_ros dyfos_node` on a ROS install; `dyfos-ros` in a venv.
            "dyfos_node = dyfos_ros.node:main",
            "dyfos-ros = dyfos_ros.node:main",
        ],
    },
)
