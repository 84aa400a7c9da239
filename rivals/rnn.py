"""The two BPTT-trained baselines of the paper's contextual-inference result.

Both are discrete-time Elman RNNs (tanh, nn.Linear readout, PyTorch's default
Kaiming-uniform initialisation) and, like the Neural ASM's offline recall, they see
inputs from the first time step only (Methods, "Network training details"). They are
trained exactly as they are recalled, so nothing differs between learning and
expression except the weight updates:

- S-to-M (sensory at mu -> motor at mu+1): the first step's sensory input is held
  for the whole roll-out (the cue stays where it was seen), and the network emits the
  motor channels of steps 1..T-1.
- SM-to-SM (sensorimotor at mu -> sensorimotor at mu+1), after Nishimoto & Tani
  (2008): the first observation goes in at step 0, then the network's own prediction
  is fed back as the next input (closed loop).

Training uses the tPC's hidden size, learning rate (and schedule), epochs, batch size
and optimiser, taken from its ``TPCConfig``, with BPTT through the whole roll-out.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn
from tqdm.auto import tqdm

from neural_asm.models.config import TPCConfig
from neural_asm.models.train import learning_rate


class SensoryToMotorRNN(nn.Module):
    def __init__(self, sensory_size: int, motor_size: int, hidden_size: int) -> None:
        super().__init__()
        self.rnn = nn.RNN(sensory_size, hidden_size, nonlinearity="tanh", batch_first=True)
        self.readout = nn.Linear(hidden_size, motor_size)

    def forward(self, sensory0: torch.Tensor, steps: int) -> torch.Tensor:
        """Motor channels (B, steps, M) of steps 1..steps from sensory input (B, S) at step 0."""
        hidden, _ = self.rnn(sensory0[:, None].expand(-1, steps, -1))
        return self.readout(hidden)


class SensorimotorRNN(nn.Module):
    def __init__(self, size: int, hidden_size: int) -> None:
        super().__init__()
        self.cell = nn.RNNCell(size, hidden_size, nonlinearity="tanh")
        self.readout = nn.Linear(hidden_size, size)

    def forward(self, x0: torch.Tensor, steps: int) -> torch.Tensor:
        """Observations (B, steps, D) of steps 1..steps, closed loop from x0 (B, D)."""
        h = x0.new_zeros(x0.shape[0], self.cell.hidden_size)
        x, out = x0, []
        for _ in range(steps):
            h = self.cell(x, h)
            x = self.readout(h)
            out.append(x)
        return torch.stack(out, dim=1)


def _optimizer(net: nn.Module, config: TPCConfig) -> torch.optim.Optimizer:
    cls = torch.optim.Adam if config.optimizer == "adam" else torch.optim.SGD
    return cls(net.parameters(), lr=config.learning_rate)


def train_rnn(
    net: nn.Module,
    first: np.ndarray,
    targets: np.ndarray,
    config: TPCConfig,
    progress: bool = False,
) -> list[float]:
    """BPTT on first-step inputs (N, I) -> target roll-outs (N, T-1, O), normalised.

    Returns the mean squared error of every epoch. Seed torch before building ``net``:
    its initial weights come from torch's global generator.
    """
    first_t = torch.as_tensor(first, dtype=torch.float32)
    targets_t = torch.as_tensor(targets, dtype=torch.float32)
    n, steps = targets_t.shape[:2]
    batch = config.batch_size or n
    optimizer = _optimizer(net, config)
    # The tPC's schedule, as a factor of the base rate.
    schedule = torch.optim.lr_scheduler.LambdaLR(optimizer, lambda epoch: learning_rate(config, epoch) / config.learning_rate)
    rng = np.random.default_rng(config.seed)
    history: list[float] = []
    for _ in tqdm(range(config.epochs), desc="BPTT", unit="epoch", disable=not progress):
        order = torch.as_tensor(rng.permutation(n))
        total = 0.0
        for start in range(0, n, batch):
            idx = order[start : start + batch]
            loss = torch.mean((net(first_t[idx], steps) - targets_t[idx]) ** 2)
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
            total += loss.item() * len(idx)
        history.append(total / n)
        schedule.step()
    return history


@torch.no_grad()
def roll_out(net: nn.Module, first: np.ndarray, steps: int) -> np.ndarray:
    """Recall (N, steps, O) from first-step inputs (N, I)."""
    net.eval()
    return net(torch.as_tensor(first, dtype=torch.float32), steps).numpy()
