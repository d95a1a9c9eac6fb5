"""The authors' released files as data: their sizes, our task of each, their layouts and
scales, and the paper's Table 3 return ranges. Imports nothing, so any module may read them."""

# Observation sizes of the paper's released files (gym -v2 MuJoCo tasks), to split [s, a].
RELEASED_OBSERVATION_SIZES = {
    "Pendulum-v1": 3,
    "Ant-v2": 111,
    "HalfCheetah-v2": 17,
    "Hopper-v2": 11,
    "Swimmer-v2": 8,
    "Walker2d-v2": 17,
}

# Action sizes of the same files: a row holds observation + action columns.
RELEASED_ACTION_SIZES = {
    "Pendulum-v1": 1,
    "Ant-v2": 8,
    "HalfCheetah-v2": 6,
    "Hopper-v2": 3,
    "Swimmer-v2": 2,
    "Walker2d-v2": 6,
}

# Our task of each released file's environment: gymnasium's -v4 tasks, which have gym -v2's
# model files and observation layouts. The authors' Ant-v2 file has none: gym v2's Ant
# observations (111: positions, velocities and contact forces) are not Ant-v4's (27).
RELEASED_TASKS = {
    "Pendulum-v1": "Pendulum-v1",
    "HalfCheetah-v2": "HalfCheetah-v4",
    "Hopper-v2": "Hopper-v4",
    "Swimmer-v2": "Swimmer-v4",
    "Walker2d-v2": "Walker2d-v4",
}

# The documented layout of the released files whose rows are whole trajectories stored one
# after another: the Pendulum file is five 200-step episodes. The MuJoCo files are not
# trajectories (the paper says so): they get no trajectory ids.
RELEASED_TRAJECTORY_LENGTHS = {"Pendulum-v1": 200}

# What the stored actions of a released file must be multiplied by to be in the environment's
# units (the authors' Pendulum file stores torque / 2); 1 for the others.
RELEASED_ACTION_SCALES = {"Pendulum-v1": 2.0}


# The paper's Table 3: (random policy, optimal policy) returns, the return range of its figures
# (their normalised returns' ends).
PAPER_RETURN_RANGES = {
    "Pendulum-v1": (-1200.96, -116.81),
    "Ant-v2": (-72.30, 4143.10),
    "HalfCheetah-v2": (-288.44, 3467.32),
    "Hopper-v2": (18.04, 3250.67),
    "Swimmer-v2": (2.31, 348.99),
    "Walker2d-v2": (1.91, 3694.13),
}

# PAPER_RETURN_RANGES's name before issue 74, kept for code outside the package that imports
# it (in the code "normalizer" is the policy's observation statistics alone).
PAPER_NORMALIZERS = PAPER_RETURN_RANGES
