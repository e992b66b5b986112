#!/usr/bin/env python3
"""Baseline for `perch bench ppo`: one PPO epoch of the subtask network in PyTorch on one CPU thread.

Same network (obs -> 64 tanh -> 64 tanh -> 21 mean, state-independent log-std; separate 2x64 tanh
value net), same batch (8192), minibatches (32 x 256), loss (clipped surrogate + clipped value
loss + entropy), global grad-norm clip 0.5 and Adam (eps 1e-5) as learner/ppo.cc. Prints one JSON
object with samples_per_s. Run with Debian's torch: /usr/bin/python3 bench/ppo_torch.py --json
(not a project dependency; tests never need it).
"""
import argparse
import json
import math
import statistics
import sys
import time

import torch
from torch import nn


def mlp(inp, out, hidden, out_gain):
    layers, last = [], inp
    for h in hidden:
        lin = nn.Linear(last, h)
        nn.init.orthogonal_(lin.weight, math.sqrt(2))
        nn.init.zeros_(lin.bias)
        layers += [lin, nn.Tanh()]
        last = h
    lin = nn.Linear(last, out)
    nn.init.orthogonal_(lin.weight, out_gain)
    nn.init.zeros_(lin.bias)
    layers.append(lin)
    return nn.Sequential(*layers)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--obs-dim", type=int, default=57)
    ap.add_argument("--act-dim", type=int, default=21)
    ap.add_argument("--batch", type=int, default=8192)
    ap.add_argument("--minibatches", type=int, default=32)
    ap.add_argument("--repeats", type=int, default=10)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()

    torch.set_num_threads(1)
    torch.manual_seed(a.seed)
    pi = mlp(a.obs_dim, a.act_dim, [64, 64], 0.01)
    vf = mlp(a.obs_dim, 1, [64, 64], 1.0)
    log_std = nn.Parameter(torch.zeros(a.act_dim))
    params = list(pi.parameters()) + [log_std] + list(vf.parameters())
    opt = torch.optim.Adam(params, lr=1e-4, eps=1e-5)
    clip, vclip, vf_coef, ent_coef, max_norm = 0.2, 0.2, 0.5, 0.0, 0.5

    n = a.batch
    obs = torch.randn(n, a.obs_dim)
    with torch.no_grad():
        mu = pi(obs)
        act = mu + torch.exp(log_std) * torch.randn(n, a.act_dim)
        dist = torch.distributions.Normal(mu, torch.exp(log_std))
        old_logp = dist.log_prob(act).sum(-1)
        old_v = vf(obs).squeeze(-1)
    adv = torch.randn(n)
    ret = old_v + torch.randn(n)
    mb = n // a.minibatches
    log2pi = math.log(2 * math.pi)

    def epoch():
        perm = torch.randperm(n)
        for m in range(a.minibatches):
            idx = perm[m * mb:(m + 1) * mb]
            o, ac, olp, ov, ad, r = obs[idx], act[idx], old_logp[idx], old_v[idx], adv[idx], ret[idx]
            ad = (ad - ad.mean()) / (ad.std(unbiased=False) + 1e-8)
            mean = pi(o)
            z = (ac - mean) * torch.exp(-log_std)
            logp = -0.5 * (z * z).sum(-1) - log_std.sum() - 0.5 * a.act_dim * log2pi
            ent = (log_std.sum() + 0.5 * a.act_dim * (1 + log2pi)).expand(mb).mean()
            ratio = torch.exp(logp - olp)
            pg = torch.max(-ad * ratio, -ad * torch.clamp(ratio, 1 - clip, 1 + clip)).mean()
            v = vf(o).squeeze(-1)
            vc = ov + torch.clamp(v - ov, -vclip, vclip)
            vl = 0.5 * torch.max((v - r) ** 2, (vc - r) ** 2).mean()
            loss = pg - ent_coef * ent + vf_coef * vl
            opt.zero_grad(set_to_none=False)
            loss.backward()
            nn.utils.clip_grad_norm_(params, max_norm)
            opt.step()

    epoch()  # warm-up
    times = []
    for _ in range(a.repeats):
        t0 = time.perf_counter()
        epoch()
        times.append(time.perf_counter() - t0)
    med = statistics.median(times)
    out = {
        "bench": "ppo",
        "impl": "torch",
        "torch_version": torch.__version__,
        "samples_per_s": n / med,
        "samples_per_s_best": n / min(times),
        "epoch_ms_median": 1e3 * med,
        "epoch_ms_min": 1e3 * min(times),
        "batch": n,
        "minibatch": mb,
        "repeats": a.repeats,
        "obs_dim": a.obs_dim,
        "act_dim": a.act_dim,
        "threads": torch.get_num_threads(),
    }
    if a.json:
        print(json.dumps(out))
    else:
        print(f"torch PPO epoch: {out['samples_per_s']:.0f} samples/s", file=sys.stdout)


if __name__ == "__main__":
    main()
