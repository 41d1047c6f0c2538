"""The loss-curve helper shared by every training loop."""
import torch

from facelib.training_log import TrainingLog


def test_training_log_writes_running_means_every_n_steps_and_at_the_end():
    log = TrainingLog(5, 2, "loss", "accuracy")
    for step in range(5):
        log.add(step, loss=torch.tensor(float(step)), accuracy=step / 10)
    h = log.history
    assert list(h) == ["step", "loss", "accuracy", "seconds"]
    assert h["step"] == [2, 4, 5]
    assert h["loss"] == [0.5, 2.5, 4.0] and h["accuracy"] == [0.05, 0.25, 0.4]
    assert len(h["seconds"]) == 3 and h["seconds"] == sorted(h["seconds"])
