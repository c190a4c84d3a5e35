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

# TUM sequence -> the folder its archive unpacks to (what `download` writes): a real sequence in a
# folder of that name fills the papers' own rows of the tables
TUM_FOLDER = {name: f"rgbd_dataset_freiburg{name[2]}_{name.split('/', 1)[1]}" for name in SYNTHETIC_ANALOGUE}
TUM_FOLDER["fr2/desk_person"] = "rgbd_dataset_freiburg2_desk_with_person"

# Paper B, Table 1 (ATE, m) and Table 2 (RPE, m): (RMSE, median, S.D.) for ORB-SLAM2 and paper B.
# s_static median of paper B is printed "0.057" (an evident 0.0057); kept as printed.
B_SEQUENCES = {"w_half": "fr3/walking_halfsphere", "w_rpy": "fr3/walking_rpy",
               "w_static": "fr3/walking_static", "w_xyz": "fr3/walking_xyz",
               "s_static": "fr3/sitting_static"}
B_TABLE1 = {
    "w_half": ((0.6173, 0.5074, 0.2495), (0.0241, 0.0184, 0.0112)),
    "w_rpy": ((0.8154, 0.6542, 0.4236), (0.0275, 0.0204, 0.0158)),
    "w_static": ((0.3518, 0.2639, 0.1607), (0.0071, 0.0054, 0.0030)),
    "w_xyz": ((0.7323, 0.6673, 0.2564), (0.0133, 0.0113, 0.0068)),
    "s_static": ((0.0085, 0.0074, 0.0042), (0.0064, 0.057, 0.0033)),
}
B_TABLE2 = {
    "w_half": ((0.4458, 0.2334, 0.2859), (0.0251, 0.0195, 0.0122)),
    "w_rpy": ((0.4803, 0.121, 0.3416), (0.0381, 0.0274, 0.0262)),
    "w_static": ((0.2214, 0.017, 0.1463), (0.0092, 0.0092, 0.0048)),
    "w_xyz": ((0.4512, 0.1653, 0.2923), (0.0179, 0.0139, 0.0090)),
    "s_static": ((0.0083, 0.0072, 0.0043), (0.0076, 0.0058, 0.0038)),
}
# Paper B, Table 3: ATE (RMSE, S.D.) in m
B_TABLE3_METHODS = ("Dyna-SLAM", "DS-SLAM", "RDS-SLAM", "paper B")
B_TABLE3 = {
    "w_half": ((0.0296, 0.0157), (0.0303, 0.0159), (0.0807, 0.0454), (0.0241, 0.0112)),
    "w_rpy": ((0.0415, 0.0271), (0.4442, 0.2350), (0.1604, 0.0873), (0.0275, 0.0158)),
    "w_static": ((0.0068, 0.0034), (0.0081, 0.0036), (0.0206, 0.012), (0.0071, 0.0030)),
    "w_xyz": ((0.0157, 0.0083), (0.0247, 0.0161), (0.0571, 0.0229), (0.0133, 0.0068)),
    "s_static": ((0.0067, 0.0046), (0.0065, 0.0033), (0.0084, 0.0043), (0.0064, 0.0033)),
}
# Paper B, Table 4: tracking time per frame (ms) on a GeForce GTX 1650: total and named stages
B_TABLE4 = {
    "ORB-SLAM2": (38.23, {}),
    "Dyna-SLAM": (672.38, {"segmentation": 198.63, "geometry": 239.52}),
    "RDS-SLAM": (85.43, {"segmentation": 200.0, "mask": 5.31}),
    "paper B": (90.56, {"segmentation": 20.48, "joint optimisation": 132.44}),
}

# Paper C, Table 1: ATE (m) (RMSE, Mean, SD) for ORB-SLAM2 and BR-SLAM (5-run means)
C_SEQUENCES = ("walking_xyz", "walking_half", "walking_rpy", "walking_static")
C_ANALOGUE = {"walking_xyz": "fr3/walking_xyz", "walking_half": "fr3/walking_halfsphere",
              "walking_rpy": "fr3/walking_rpy", "walking_static": "fr3/walking_static"}
C_TABLE1 = {
    "walking_xyz": ((0.2954, 0.2628, 0.0135), (0.0135, 0.0114, 0.0071)),
    "walking_half": ((0.2092, 0.1752, 0.1142), (0.0185, 0.0162, 0.0089)),
    "walking_rpy": ((0.1567, 0.1404, 0.0700), (0.0265, 0.0221, 0.0145)),
    "walking_static": ((0.0192, 0.0162, 0.0103), (0.0055, 0.0048, 0.0027)),
}
# Paper C, Tables 2-4: (RMSE, SD) of ATE (m), RTE (m), RRE (deg) per system
C_OTHER_METHODS = ("SLAM-PCD", "DynaSLAM", "DS-SLAM", "RDS-SLAM", "BR-SLAM")
C_TABLE2 = {
    "walking_xyz": ((0.0241, 0.0122), (0.0188, 0.0094), (0.0333, 0.0229), (0.0281, 0.0167), (0.0135, 0.0071)),
    "walking_half": ((0.0453, 0.0316), (0.0271, 0.0155), (0.0297, 0.0152), (0.0282, 0.0155), (0.0185, 0.0089)),
    "walking_rpy": ((0.0077, 0.0039), (0.0371, 0.0244), (0.1503, 0.1168), (0.1114, 0.0920), (0.0265, 0.0145)),
    "walking_static": ((0.0157, 0.0084), (0.0074, 0.0038), (0.0102, 0.0038), (0.0419, 0.0348), (0.0055, 0.0027)),
}
C_TABLE3 = {
    "walking_xyz": ((0.0204, 0.0107), (0.0217, 0.0119), (0.0333, 0.0229), (0.0281, 0.0167), (0.0120, 0.0072)),
    "walking_half": ((0.0274, 0.0140), (0.0284, 0.0149), (0.0297, 0.0152), (0.0282, 0.0155), (0.0126, 0.0076)),
    "walking_rpy": ((0.0616, 0.0357), (0.0448, 0.0262), (0.1503, 0.1168), (0.1114, 0.0920), (0.0169, 0.0103)),
    "walking_static": ((0.0102, 0.0049), (0.0089, 0.0044), (0.0102, 0.0038), (0.0419, 0.0348), (0.0051, 0.0027)),
}
C_TABLE4 = {
    "walking_xyz": ((0.6227, 0.3807), (0.6284, 0.3848), (0.8266, 0.2826), (0.7236, 0.4435), (0.3890, 0.2740)),
    "walking_half": ((0.7440, 0.3459), (0.7842, 0.4012), (0.8142, 0.4101), (0.8216, 0.4347), (0.3921, 0.2062)),
    "walking_rpy": ((1.3831, 0.8318), (0.9894, 0.5701), (3.0042, 2.3065), (9.3192, 8.5720), (0.4447, 0.2494)),
    "walking_static": ((0.2631, 0.1119), (0.2612, 0.1259), (0.2690, 0.1215), (1.1686, 0.9917), (0.1652, 0.0838)),
}
