//! Motion: canonical commands to machine-frame moves, lookahead planning, kinematics and the
//! realtime interpolator that turns the segment queue into axis setpoints.
