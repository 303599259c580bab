"""Import robot recordings (ROS 2 bags, LeRobot datasets, MimicGen HDF5) as demonstrations
(``cpmp-import``).

python scripts/import.py mapping=conf/import/rosbag_example.yaml input=my_bags/
"""

from cpmp.cli.main import import_main

if __name__ == "__main__":
    import_main()
