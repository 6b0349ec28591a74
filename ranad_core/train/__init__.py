"""Training RaNAD on `ranad synth` datasets: pairs and augmentation (data.py), losses (losses.py), the loop with
checkpoints and resume (trainer.py)."""
