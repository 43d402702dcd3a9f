# --- snakekit's ROS image: the students' image (the kit, its venv) with Debian bookworm's own ROS 1
# (Noetic era): roscore, rospy and the messages `snakekit ros` needs, rosbag and rostopic,
# robot_state_publisher, RViz, and a virtual display served to the browser by noVNC on one port.
# compose's `ros` profile builds and runs it (docker/compose.yaml, docs/ros.md):
#   docker compose -f docker/compose.yaml --profile ros up rviz
# The students' stages above are docker/Dockerfile's, so the kit and its venv are the same layers
# as the students' image's: only Debian's packages and a few files are added.
FROM students AS ros
SHELL ["/bin/bash", "-o", "pipefail", "-c"]
USER 0:0
# ROS 1 (python3-rospy, the messages (tf2_msgs for `rostopic echo /tf`), roslaunch's roscore,
# rostopic, rosbag, rosnode, rosparam), robot_state_publisher, RViz; Xvfb (the display), x11vnc
# (VNC of it), noVNC + websockify (VNC in the browser, one port). Mesa's software GL is the lab's (MuJoCo's EGL) and serves RViz's GLX.
# hadolint ignore=DL3008
RUN apt-get update \
 && DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends \
      python3-rospy python3-sensor-msgs python3-trajectory-msgs python3-roslaunch python3-rostopic \
      python3-rosbag python3-rosnode python3-rosparam python3-tf2-msgs ros-robot-state-publisher rviz \
      xvfb x11vnc novnc libgl1-mesa-dri \
 && rm -rf /var/lib/apt/lists/* /var/cache/apt/*.bin /var/log/apt /var/log/dpkg.log
COPY docker/ros/arm.rviz docker/ros/start-rviz docker/ros/wait-for-master /opt/snakekit/docker/ros/
RUN ln -s /opt/snakekit/docker/ros/start-rviz /opt/snakekit/docker/ros/wait-for-master /usr/local/bin/
USER 1000:1000
# (the lab's health check is JupyterLab's; compose gives roscore its own)
HEALTHCHECK NONE
EXPOSE 8080
CMD ["bash"]
