"""Install wafer_planner_ros as an ament_python package."""

from glob import glob

from setuptools import find_packages, setup

package_name = 'wafer_planner_ros'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
    ],
    install_requires=['setuptools'],
    extras_require={'test': ['pytest', 'hypothesis', 'rosbags'],
                    # wafer-study: --ray runs on a Ray cluster, --search is an Optuna search
                    'ray': ['ray[default]'], 'search': ['optuna']},
    zip_safe=True,
    maintainer='wafer_planner_ros developers',
    maintainer_email='wafer-planner@example.com',
    description='Wafer-transfer robot planner: PRM with certified edges, B-spline trajectories',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'wafer-roadmap = wafer_planner_ros.cli.roadmap:entry_point',
            'wafer-plan = wafer_planner_ros.cli.plan:entry_point',
            'wafer-plan-client = wafer_planner_ros.cli.client:entry_point',
            'wafer-kernels = wafer_planner_ros.cli.kernels:entry_point',
            'wafer-recover = wafer_planner_ros.cli.recover:entry_point',
            'wafer-replay = wafer_planner_ros.cli.replay:entry_point',
            'wafer-review = wafer_planner_ros.cli.review:entry_point',
            'wafer-study = wafer_planner_ros.cli.study:entry_point',
            'wafer-sim = wafer_planner_ros.node.sim:entry_point',
            'wafer_planner_node = wafer_planner_ros.node.main:entry_point',
        ],
    },
)
