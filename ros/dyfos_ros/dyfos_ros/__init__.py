"""dyfos_ros: the ``dyfos`` ROS 2 node (:mod:`dyfos_ros.node`) over the ``dyfos`` Python binding."""
