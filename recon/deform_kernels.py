"""The deformation MLP at several times, forward and backward written out by hand.

`DeformationField.forward_times_autograd` (recon.deform) is the readable version: linear layers and
ReLUs that autograd differentiates. `mlp_times` computes the same outputs and the same weight
gradients (tests/recon/test_deform_kernels.py, float64 to rounding) with less traffic through memory,
which is what bounds a 4 x 96 field on a 2-core CPU:

- one time at a time goes through all the layers, forward and then backward, so its hidden states
  stay in the cache between layers (one [K N, w] product per layer, or blocks of fewer rows, measured
  slower);
- ReLUs run in place on the products' outputs, and the saved post-ReLU states double as the masks of
  the backward (h > 0 exactly where the pre-activation was > 0);
- the three heads (position 3, quaternion 4, log-scale 3) are one [w, 10] product forward and backward;
- the position columns of the two layers that read the encoded input (the first and the one after
  the skip) are shared by every time: their products gamma(x) W_x are computed once, and their weight
  gradient is one product of gamma(x) with the gradients summed over the times; the time columns are a
  per-time bias whose gradient is an outer product.

Everything else is the field of recon.deform: weights, layout, initialisation, and the time encoding.
"""
from __future__ import annotations

import torch

HEADS = (3, 4, 3)        # dx, dq, dlog_s


class _MLPTimes(torch.autograd.Function):
    """(ex [N, n_x], et [K, n_t], skip, W_0, b_0, .., W_{d-1}, b_{d-1}, W_head [10, w], b_head [10])
    -> K outputs [N, 10], the heads at each time."""

    @staticmethod
    def forward(ctx, ex, et, skip, *params):
        d = (len(params) - 2) // 2
        weights, biases, w_head, b_head = params[0:2 * d:2], params[1:2 * d:2], params[-2], params[-1]
        n_x, k_times = ex.shape[1], et.shape[0]
        n_emb = n_x + et.shape[1]
        s = skip + 1 if skip + 1 < d else None            # the layer that reads the encoded input again

        def shared(i):        # gamma(x) W_x [N, w], gamma(t) W_t + b [K, w]
            w = weights[i]
            return ex @ w[:, :n_x].t(), torch.addmm(biases[i], et, w[:, n_x:n_emb].t())

        (a0, c0), (a_s, c_s) = shared(0), (shared(s) if s is not None else (None, None))
        w_t = [(w if i != s else w[:, n_emb:]).t() for i, w in enumerate(weights)]
        outs, hidden = [], []
        for k in range(k_times):             # one time at a time: its states stay in the cache
            h = (a0 + c0[k]).relu_()
            hidden.append(h)
            for i in range(1, d):
                h = (torch.addmm(a_s, h, w_t[i]).add_(c_s[k]) if i == s
                     else torch.addmm(biases[i], h, w_t[i])).relu_()
                hidden.append(h)
            outs.append(torch.addmm(b_head, h, w_head.t()))
        ctx.save_for_backward(ex, et, *params, *hidden)
        ctx.meta = (d, s, k_times)
        return tuple(outs)

    @staticmethod
    def backward(ctx, *g_outs):
        d, s, k_times = ctx.meta
        ex, et, *rest = ctx.saved_tensors
        params, hidden = rest[:2 * d + 2], rest[2 * d + 2:]
        weights, w_head = params[0:2 * d:2], params[-2]
        n_x = ex.shape[1]
        n_emb = n_x + et.shape[1]
        encoded = (0, s) if s is not None else (0,)
        w_h = [w if i != s else w[:, n_emb:] for i, w in enumerate(weights)]
        g_w = [None if i == 0 else torch.zeros_like(w) for i, w in enumerate(w_h)]   # the hidden columns
        g_b = [torch.zeros_like(w[:, 0]) for w in weights]
        g_time = {i: [] for i in encoded}     # per time: the gradient summed over the Gaussians [w]
        g_shared = {}                         # summed over the times [N, w]
        g_w_head = torch.zeros_like(w_head)
        g_b_head = torch.zeros_like(params[-1])
        for k, g_out in enumerate(g_outs):
            h = hidden[k * d:(k + 1) * d]
            g_w_head.addmm_(g_out.t(), h[-1])
            g_b_head += g_out.sum(0)
            g = g_out @ w_head                                # [N, w]
            for i in range(d - 1, -1, -1):
                g = torch.ops.aten.threshold_backward.grad_input(g, h[i], 0, grad_input=g)   # in place: g is our own
                if i in g_time:
                    g_time[i].append(g.sum(0))
                    g_shared[i] = g if i not in g_shared else g_shared[i].add_(g)
                else:
                    g_b[i] += g.sum(0)
                if i > 0:
                    g_w[i].addmm_(g.t(), h[i - 1])
                    g = g @ w_h[i]
        for i in encoded:
            g_t = torch.stack(g_time[i])                      # [K, w]
            parts = [g_shared[i].t() @ ex, g_t.t() @ et] + ([g_w[i]] if i > 0 else [])
            g_w[i], g_b[i] = torch.cat(parts, 1), g_t.sum(0)
        flat = [t for pair in zip(g_w, g_b) for t in pair]
        return (None, None, None, *flat, g_w_head, g_b_head)


def mlp_times(field, ex: torch.Tensor, et: torch.Tensor):
    """`field` (a recon.deform.DeformationField), ex [N, n_x] = gamma(x), et [K, n_t] = gamma(t)
    -> K (dx [N, 3], dq [N, 4], dlog_s [N, 3]); the same values and gradients as
    field.forward_times_autograd at those encodings."""
    params = [p for layer in field.layers for p in (layer.weight, layer.bias)]
    w_head = torch.cat([field.warp.weight, field.rotation.weight, field.scaling.weight])     # [10, w]
    b_head = torch.cat([field.warp.bias, field.rotation.bias, field.scaling.bias])
    outs = _MLPTimes.apply(ex, et, field.skip, *params, w_head, b_head)
    return [tuple(out.split(HEADS, dim=1)) for out in outs]
