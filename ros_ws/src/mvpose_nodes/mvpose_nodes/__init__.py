"""mvpose: markerless multi-camera 3D human motion capture on ROS 2 Jazzy."""
