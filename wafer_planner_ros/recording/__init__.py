"""
Recording every query to MCAP in the rosbag2 layout, and reading it back (ROS-free).

Where a change belongs: the file format and writing records, ``bag`` (message definitions:
``msgdefs``; what a recording holds besides messages: ``contents``); the writer thread and
its queue, ``recorder``; when a file is finished and the next begun, ``splitting``; how
many files are kept, ``retention``; reading, ``reading`` and ``queries`` (a request with its
answer); comparing answers, ``compare``; completing a file cut off by a crash, ``recover``.
"""
