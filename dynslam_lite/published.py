"""Numbers printed in the three papers, for the "published" columns of the tables only.

Transcribed from the papers (see ``../shared/papers/README.md``); never used as targets. Every
table that shows them labels them as published, beside what this project measured.
"""
from __future__ import annotations

# Paper A, Table 1: RPE RMSE of the odometry, (translation m/s, rotation deg/s)
A_TABLE1_METHODS = ("DVO", "BaMVO", "ref. [19]", "paper A")
A_TABLE1 = {
    "fr2/desk_person": ((0.0354, 0.0352, 0.0069, 0.0099), (1.5368, 1.2159, 0.4380, 0.4247)),
    "fr3/sitting_static": ((0.0157, 0.0248, 0.0077, 0.0083), (0.6084, 0.6977, 0.2595, 0.2677)),
    "fr3/sitting_xyz": ((0.0453, 0.0482, 0.0117, 0.0173), (1.4980, 1.3885, 0.4997, 0.4980)),
    "fr3/sitting_rpy": ((0.1735, 0.1872, 0.0234, 0.0233), (6.0164, 5.9834, 0.7838, 0.7134)),
    "fr3/sitting_halfsphere": ((0.1005, 0.0598, 0.0245, 0.0463), (4.6490, 2.8804, 0.5643, 0.9621)),
    "fr3/walking_static": ((0.3818, 0.1339, 0.1881, 0.0306), (6.5302, 2.0833, 3.2101, 0.5882)),
    "fr3/walking_xyz": ((0.4360, 0.2326, 0.2158, 0.1006), (7.6669, 4.3911, 3.6476, 1.9498)),
    "fr3/walking_rpy": ((0.4038, 0.3584, 0.3270, 0.1415), (7.0662, 6.3398, 6.3215, 2.3033)),
    "fr3/walking_halfsphere": ((0.2638, 0.1738, 0.1908, 0.1121), (5.2179, 4.2863, 3.3321, 2.1003)),
}

# Paper A, Table 2: ATE (m) as (max, min, RMSE)
A_TABLE2_METHODS = ("ORB-SLAM2", "ref. [5]", "paper A")
A_TABLE2 = {
    "fr3/walking_static": ((0.6506, 0.0646, 0.3902), (0.6161, 0.0231, 0.3080), (0.1523, 0.0007, 0.0218)),
    "fr3/walking_xyz": ((1.4540, 0.0590, 0.6731), (0.8190, 0.0430, 0.3047), (0.4584, 0.0034, 0.0799)),
    "fr3/walking_rpy": ((1.7196, 0.0285, 0.8004), (0.9351, 0.0708, 0.4983), (0.4678, 0.0171, 0.1510)),
    "fr3/walking_halfsphere": ((1.6433, 0.0463, 0.5571), (0.6246, 0.1088, 0.3116), (0.4065, 0.0057, 0.1147)),
}

# TUM sequence -> the synthetic scene that imitates it (camera motion and people)
SYNTHETIC_ANALOGUE = {
    "fr3/sitting_static": "sitting_static",
    "fr3/sitting_xyz": "sitting_xyz",
    "fr3/sitting_rpy": "sitting_rpy",
    "fr3/sitting_halfsphere": "sitting_halfsphere",
    "fr3/walking_static": "walking_static",
    "fr3/walking_xyz": "walking_xyz",
    "fr3/walking_rpy": "walking_rpy",
    "fr3/walking_halfsphere": "walking_halfsphere",
}
