"""The world the controller lives in: heart motion, sensors, plant, closed loop, metrics."""
