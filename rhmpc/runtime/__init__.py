"""The deployment on one machine: the controller, its predictor, its sensor and its robot as
separate processes over UDP (``rhmpc sil``).

==============  =================================================================
``wire``        the wire format (version 1, CRTK names) and a tracker-side Python client
``build``       the exported controller and its real-time program, built with CMake
``processes``   the sensor, the predictor and the robot (the simulator in real time)
``host``        the host's own wake-up latency: cyclictest, or the controller's probe
``deployment``  one run of every process, stopped together; what it measured
``c/``          the controller's program, the wire format in C, a robot-side C client
==============  =================================================================
"""
