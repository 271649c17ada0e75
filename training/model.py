"""The three intention-net networks of Gao et al. (CoRL 2017, section 3.2) in PyTorch.

* DLM-Net  -- camera features concatenated with the intention one-hot expanded to 64-d; one
              head per intention (a branched head) and the given one-hot selects one.
* LPE-Net  -- camera image and LPE image through CNN backbones, concatenated, MLP.
* None     -- the Non-Intention Net ablation: camera only.

Every network ends in tanh: the output is (v, omega) normalised to [-1, 1] by the robot's
limits, exactly the dataset's `label`. The ONNX contract (DESIGN.md section 5) names the inputs
`camera` f32[N,3,H,W], `intention` f32[N,4] and `lpe` f32[N,3,P,P], and the output `control`;
`forward` takes the inputs in that order.

Backbones:

* `small` (default): five 3x3/5x5 convolutions with batch norm and ReLU, four of them strided,
  then a global average pool -- about 0.4 M parameters, trains on two CPU cores at 96-128 px.
  The paper uses ResNet-50 (2048-d features); this is the CPU-sized stand-in, named in the card.
* `resnet50`: torchvision's ResNet-50 without its classifier, randomly initialised (nothing is
  downloaded); for GPU runs. Needs torchvision.

The LPE branch (`lpe_branch`):

* `light` (default): a separate, narrower small CNN for the LPE drawing. The paper shares one
  siamese backbone between the camera and the LPE image; a camera photo and a flat colour-coded
  drawing are different inputs, and a narrower branch halves the LPE-Net's CPU cost. Listed as a
  deviation in the card.
* `shared`: the paper's siamese backbone (one set of weights for both images).
* `separate`: a second backbone of the camera's size with its own weights.
"""

from __future__ import annotations

import torch
from torch import nn

KINDS = ("dlm", "lpe", "none")
BACKBONES = ("small", "small-spatial", "resnet50")
LPE_BRANCHES = ("light", "shared", "separate")
# Channel widths of the small CNN's five convolutions; the light LPE branch is narrower.
SMALL_WIDTHS = (24, 32, 64, 128, 256)
LIGHT_WIDTHS = (16, 24, 32, 64, 128)
# The wider small CNN of `small-spatial` (GPU-trained, still a few ms per frame on one core).
SPATIAL_WIDTHS = (32, 48, 96, 192, 256)
INTENTION_DIM = 4  # turn_left, turn_right, go_forward, stop (protocol::Dlm::index)
INTENTION_EMBED = 64  # the paper expands the 4-d one-hot to 64-d
HEAD_HIDDEN = 96
DROPOUT = 0.2


def conv_bn_relu(cin: int, cout: int, kernel: int, stride: int) -> nn.Sequential:
    # No conv bias: batch norm's shift makes it redundant.
    return nn.Sequential(
        nn.Conv2d(cin, cout, kernel, stride=stride, padding=kernel // 2, bias=False),
        nn.BatchNorm2d(cout),
        nn.ReLU(inplace=True),
    )


class SpatialPool(nn.Module):
    """Global average pool plus a spatial soft-argmax per channel (Levine et al. 2016's
    "spatial softmax"): for each channel the expected image x and y under a softmax over its
    map, in [-1, 1]. The average pool says *what* the image holds, the keypoints *where* (a
    person left or right of the path, how far up the image a door frame reaches), which a
    plain global average pool throws away. Independent of the input size; exports to plain
    Softmax/Mul/ReduceSum."""

    def __init__(self, channels: int):
        super().__init__()
        # Learned sharpness of the softmax (log scale), one per channel.
        self.log_temperature = nn.Parameter(torch.zeros(1, channels, 1))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        n, c, h, w = x.shape
        flat = x.flatten(2)  # [N, C, H*W]
        att = torch.softmax(flat * torch.exp(self.log_temperature), dim=-1)
        ys = torch.linspace(-1.0, 1.0, h, device=x.device, dtype=x.dtype)
        xs = torch.linspace(-1.0, 1.0, w, device=x.device, dtype=x.dtype)
        gy = ys.view(h, 1).expand(h, w).reshape(1, 1, h * w)
        gx = xs.view(1, w).expand(h, w).reshape(1, 1, h * w)
        ex = (att * gx).sum(dim=-1)
        ey = (att * gy).sum(dim=-1)
        return torch.cat([flat.mean(dim=-1), ex, ey], dim=1)


class SmallCNN(nn.Module):
    """Five conv-BN-ReLU layers (strides 2, 2, 2, 2, 1) and a global average pool (or, with
    `spatial`, the average pool plus per-channel soft-argmax keypoints: 3x the features).

    At 96 px the feature maps are 48, 24, 12, 6 and 6 px wide; the last layer's receptive field
    covers the whole image. Works for any input size >= 16 px."""

    def __init__(self, widths: tuple[int, ...] = SMALL_WIDTHS, spatial: bool = False):
        super().__init__()
        w = widths
        pool = [SpatialPool(w[4])] if spatial else [nn.AdaptiveAvgPool2d(1), nn.Flatten()]
        self.features = nn.Sequential(
            conv_bn_relu(3, w[0], 5, 2),
            conv_bn_relu(w[0], w[1], 3, 2),
            conv_bn_relu(w[1], w[2], 3, 2),
            conv_bn_relu(w[2], w[3], 3, 2),
            conv_bn_relu(w[3], w[4], 3, 1),
            *pool,
        )
        self.out_dim = w[4] * (3 if spatial else 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.features(x)


class ResNet50(nn.Module):
    """torchvision's ResNet-50 cut at the average pool (2048-d), random initialisation."""

    def __init__(self):
        super().__init__()
        try:
            import torchvision
        except ImportError as e:  # only the GPU recipe needs it; say so instead of a traceback
            raise SystemExit(
                "--backbone resnet50 needs torchvision (pip install torchvision matching your "
                "torch); the default --backbone small does not"
            ) from e
        net = torchvision.models.resnet50(weights=None)
        net.fc = nn.Identity()
        self.net = net
        self.out_dim = 2048

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net(x)


def make_backbone(name: str, light: bool = False) -> nn.Module:
    if name == "small":
        return SmallCNN(LIGHT_WIDTHS if light else SMALL_WIDTHS)
    if name == "small-spatial":
        return SmallCNN(LIGHT_WIDTHS if light else SPATIAL_WIDTHS, spatial=True)
    if name == "resnet50":
        # A "light" ResNet branch would be a different architecture; the small CNN is the light
        # branch for both backbones.
        return SmallCNN(LIGHT_WIDTHS) if light else ResNet50()
    raise ValueError(f"unknown backbone {name!r} (one of {BACKBONES})")


def mlp_head(cin: int, hidden: int = HEAD_HIDDEN) -> nn.Sequential:
    return nn.Sequential(nn.Linear(cin, hidden), nn.ReLU(inplace=True), nn.Dropout(DROPOUT), nn.Linear(hidden, 2))


class DlmNet(nn.Module):
    """Camera features (+) intention -> Dense(64); one MLP head per intention, tanh.

    The head selection is a sum of all heads' outputs weighted by the one-hot, so the exported
    graph is plain Mul/ReduceSum (no gather on a data-dependent index) and a one-hot selects
    exactly one head."""

    def __init__(self, backbone: str = "small"):
        super().__init__()
        self.camera = make_backbone(backbone)
        self.intention = nn.Sequential(nn.Linear(INTENTION_DIM, INTENTION_EMBED), nn.ReLU(inplace=True))
        cin = self.camera.out_dim + INTENTION_EMBED
        self.dropout = nn.Dropout(DROPOUT)
        self.heads = nn.ModuleList(mlp_head(cin) for _ in range(INTENTION_DIM))

    @torch.no_grad()
    def copy_intention(self, source: int, target: int) -> None:
        """Makes one-hot index `target` drive as `source` does: its head and its column of the
        intention embedding become copies of `source`'s. A warm start for an intention the
        network was never trained on (the arriving `stop` from `go_forward`), which the
        fine-tune then teaches to differ."""
        self.heads[target].load_state_dict(self.heads[source].state_dict())
        weight = self.intention[0].weight
        weight[:, target] = weight[:, source]

    def forward(self, camera: torch.Tensor, intention: torch.Tensor) -> torch.Tensor:
        x = torch.cat([self.camera(camera), self.intention(intention)], dim=1)
        x = self.dropout(x)
        per_head = torch.stack([h(x) for h in self.heads], dim=1)  # [N, 4, 2]
        picked = (per_head * intention.unsqueeze(-1)).sum(dim=1)  # [N, 2]
        return torch.tanh(picked)


class LpeNet(nn.Module):
    """Camera and LPE image through backbones (shared or separate), concatenated, MLP, tanh."""

    def __init__(self, backbone: str = "small", lpe_branch: str = "light"):
        super().__init__()
        if lpe_branch not in LPE_BRANCHES:
            raise ValueError(f"unknown lpe branch {lpe_branch!r} (one of {LPE_BRANCHES})")
        self.lpe_branch = lpe_branch
        self.camera = make_backbone(backbone)
        # Shared: the paper's siamese network; the same module object runs both images.
        self.lpe = self.camera if lpe_branch == "shared" else make_backbone(backbone, light=lpe_branch == "light")
        cin = self.camera.out_dim + self.lpe.out_dim
        self.head = nn.Sequential(nn.Dropout(DROPOUT), mlp_head(cin, 128))

    def forward(self, camera: torch.Tensor, lpe: torch.Tensor) -> torch.Tensor:
        x = torch.cat([self.camera(camera), self.lpe(lpe)], dim=1)
        return torch.tanh(self.head(x))


class NoneNet(nn.Module):
    """The Non-Intention Net: camera only."""

    def __init__(self, backbone: str = "small"):
        super().__init__()
        self.camera = make_backbone(backbone)
        self.head = nn.Sequential(nn.Dropout(DROPOUT), mlp_head(self.camera.out_dim, 128))

    def forward(self, camera: torch.Tensor) -> torch.Tensor:
        return torch.tanh(self.head(self.camera(camera)))


def build(config: dict) -> nn.Module:
    """The network a model config describes: {kind, backbone, lpe_branch}. Training and export
    both build from the config stored in the checkpoint, so they cannot disagree."""
    kind = config["kind"]
    backbone = config.get("backbone", "small")
    if backbone not in BACKBONES:
        raise ValueError(f"unknown backbone {backbone!r} (one of {BACKBONES})")
    if kind == "dlm":
        return DlmNet(backbone)
    if kind == "lpe":
        return LpeNet(backbone, config.get("lpe_branch", "light"))
    if kind == "none":
        return NoneNet(backbone)
    raise ValueError(f"unknown kind {kind!r} (one of {KINDS})")


def input_names(kind: str) -> list[str]:
    """The ONNX input names in forward's argument order (the agent's contract)."""
    return {"dlm": ["camera", "intention"], "lpe": ["camera", "lpe"], "none": ["camera"]}[kind]


def describe(config: dict) -> str:
    """Free-text backbone description for the card's `backbone` key."""
    b = config.get("backbone", "small")
    cam = {
        "small": f"small-cnn 5 conv (widths {'-'.join(map(str, SMALL_WIDTHS))}, BN, ReLU, strides 2-2-2-2-1) + global avg pool",
        "small-spatial": f"small-cnn 5 conv (widths {'-'.join(map(str, SPATIAL_WIDTHS))}, BN, ReLU, strides 2-2-2-2-1) "
        "+ global avg pool and spatial soft-argmax keypoints per channel",
        "resnet50": "resnet50 (torchvision, random init, cut at avg pool, 2048-d)",
    }[b]
    if config["kind"] == "dlm":
        return f"{cam}; intention 4->64; 4 branched MLP heads ({HEAD_HIDDEN} hidden) selected by the one-hot; tanh"
    if config["kind"] == "lpe":
        branch = config.get("lpe_branch", "light")
        lpe = {
            "shared": "LPE through the same (siamese, shared) backbone",
            "separate": "LPE through a second backbone of the same architecture (own weights)",
            "light": f"LPE through a separate light small-cnn (widths {'-'.join(map(str, LIGHT_WIDTHS))}"
            + (", avg pool and keypoints)" if b == "small-spatial" else ")"),
        }[branch]
        return f"{cam}; {lpe}; concatenated, MLP (128 hidden); tanh"
    return f"{cam}; MLP (128 hidden); tanh"


def count_parameters(model: nn.Module) -> int:
    # Shared (siamese) modules are one set of parameters; parameters() already deduplicates.
    return sum(p.numel() for p in model.parameters())


def freeze_batch_norm_statistics(net: nn.Module) -> None:
    """Puts every batch norm of `net` in eval mode, so that training uses and keeps its running
    statistics (its scale and shift still get gradients). Called after each
    `net.train()`, which would switch them back. A fine-tune from a shipped model otherwise
    re-estimates the statistics on its own, narrower data (round 30's suspect for the glass door
    every DLM-Net fine-tune forgot)."""
    for m in net.modules():
        if isinstance(m, nn.modules.batchnorm._BatchNorm):
            m.eval()
