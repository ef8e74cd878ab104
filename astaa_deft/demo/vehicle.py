"""The ego vehicle's dimensions and limits, shared by simulator, planner and controller."""

LENGTH = 4.6  # m, bumper to bumper
WIDTH = 1.9  # m
WHEELBASE = 2.8  # m; the axles sit symmetrically about the box centre
MAX_STEERING = 0.5  # rad at the front wheels
MAX_ACCELERATION = 3.0  # m/s², what the powertrain can do
MAX_DECELERATION = 8.0  # m/s², what the brakes can do (a full stop)
