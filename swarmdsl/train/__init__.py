"""`swarmdsl train`: fit the small networks `nn(...)` calls, from hard-coded rules.

Importing this package does not import torch; `fit.train` does, when it runs.
"""

from swarmdsl.train.data import TASKS, Task
from swarmdsl.train.fit import TrainConfig, TrainResult, percentage_error, train

__all__ = ["TASKS", "Task", "TrainConfig", "TrainResult", "percentage_error", "train"]
