"""Inference: kinematics and beta -> the confidence interval on mu (the ball-model fit) and the report's running max."""
