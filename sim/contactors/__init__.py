"""What presses the skin: `ContactorSpec` and `PressPlan`, hands of simulated people (kinematics,
subjects, the paper's interactions), objects, body parts, and where each presses."""
