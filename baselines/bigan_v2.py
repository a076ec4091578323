"""BiGAN version 2: the BiGAN of the authors' paper-era code (the paper's BiGAN column).

`bigan@1` (baselines/bigan.py) follows Donahue et al.'s paper. Version 2 is the run the authors
scored as "BiGAN" in the paper's figures: CNN-GAN/Top-Mapping at commit 25be0fd,
`src/plot/plotPaper2.py:17,25,28,30` (`ALI/ALI`, checkpoint 22, i.e. 2200 iterations: tested
as `net_en_%d00`, model.py:489-492), method `ALI` of `src/model/model.py`:

* the networks of `baselines/authors_nets.py` (encoder, decoder, joint critic), no side critics
  and no cycle loss (model.py:127-129 defines only the joint losses for it);
* least-squares joint losses (model.py:128-129, `mae_criterion` = mean squared error);
* one iteration (model.py:308-312): one joint-critic step, then `g_iter` = 8 joint-generator
  steps on the same batch of 64 maps and 64 codes z ~ N(0, I) (one `feed_datas`, :309, which
  turns the joint critic's dropout on, :179-181); Adam lr 2e-4, beta1 0.5 for both
  (model.py:219-222).

`iterations` defaults to 2200, the checkpoint their figures use (plotPaper2.py:25); the other
parameters and every choice not listed here are `stable_afl@2`'s (methods/stable_afl_v2.py).
"""

from __future__ import annotations

from collections.abc import Sequence

import torch

from methods.stable_afl_v2 import AuthorsRecipe
from safl_bench.methods.method import register_method


@register_method
class BiGAN2(AuthorsRecipe):
    """BiGAN as its authors' paper-era code trained it (least squares, 1 critic : 8 generator steps)."""

    name = "bigan"
    default_iterations = 2200

    def build_optimizers(self) -> dict[str, torch.optim.Optimizer]:
        return {"joint": self._adam("joint"), "generator": self._adam("encoder", "decoder")}

    def train_step(self, batches: Sequence[torch.Tensor], gen: torch.Generator) -> dict[str, float]:
        """One iteration of model.py:308-312 at 25be0fd."""
        x = batches[0]
        z = self.sample_prior(len(x), gen)
        stats = {"loss_dj": self._joint_critic_step(x, z), "loss_g": 0.0}
        for _ in range(self.gen_steps):
            stats["loss_g"] += self._joint_generator_step(x, z) / self.gen_steps
        return stats
