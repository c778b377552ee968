"""RLAD: SAC from pixels with A-LIX, DrQ augmentation, WayConv1D, the traffic-light
auxiliary loss and a replay that stores each camera frame once. ``sac.py`` reads top to bottom."""
