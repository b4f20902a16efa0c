"""The truncated tensor algebra in plain torch: products, exp, log and path signatures.

A truncated tensor is a list of levels [x_0, x_1, ..., x_m], level k of shape [N, d**k] with
the index (i_1, ..., i_k) at flat position i_1 d^(k-1) + ... + i_k (pysiglib's layout). This is
the reference the `signatory` summarizer's pysiglib backend is tested and benchmarked against,
and its `torch` backend (for devices that pysiglib was not built for).
"""

from __future__ import annotations

import torch


def outer(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """[N, d^i] x [N, d^j] -> [N, d^(i+j)]."""
    return (a[:, :, None] * b[:, None, :]).flatten(1)


def multiply(a: list[torch.Tensor], b: list[torch.Tensor]) -> list[torch.Tensor]:
    """Truncated tensor product a ⊗ b at the depth of a and b."""
    return [sum(outer(a[i], b[k - i]) for i in range(k + 1)) for k in range(len(a))]


def exp_increment(delta: torch.Tensor, depth: int) -> list[torch.Tensor]:
    """exp(delta) = sum_k delta^{⊗k} / k! for delta [N, d]: the signature of one straight segment."""
    levels = [torch.ones_like(delta[:, :1])]
    for k in range(1, depth + 1):
        levels.append(outer(levels[-1], delta) / k)
    return levels


def chen_step(sig: list[torch.Tensor], delta: torch.Tensor) -> list[torch.Tensor]:
    """sig ⊗ exp(delta): the signature extended by one straight segment with increment delta [N, d].

    Level k is sum_i sig_i ⊗ delta^{⊗(k-i)} / (k-i)!, evaluated Horner-style,
    (((delta/k + sig_1) ⊗ delta/(k-1) + sig_2) ⊗ delta/(k-2) + ...) ⊗ delta + sig_k,
    so that each product is with the vector delta rather than between two tensors.
    """
    out = [sig[0]]
    for k in range(1, len(sig)):
        acc = delta / k
        for i in range(1, k):
            acc = outer(acc + sig[i], delta) / (k - i)
        out.append(sig[k] + acc)
    return out


def signature(path: torch.Tensor, depth: int) -> list[torch.Tensor]:
    """Truncated signature of the piecewise-linear path [N, L, d], by Chen's identity over its segments."""
    increments = path[:, 1:] - path[:, :-1]
    sig = exp_increment(increments[:, 0], depth)
    for t in range(1, increments.shape[1]):
        sig = chen_step(sig, increments[:, t])
    return sig


def log(x: list[torch.Tensor]) -> list[torch.Tensor]:
    """Truncated logarithm of a tensor with scalar part 1: sum_m (-1)^(m+1) (x - 1)^{⊗m} / m."""
    y = [torch.zeros_like(x[0])] + x[1:]
    power, out = y, list(y)
    for m in range(2, len(x)):
        power = multiply(power, y)
        out = [o + (-1) ** (m + 1) * p / m for o, p in zip(out, power)]
    return out


def lyndon_words(dim: int, depth: int) -> list[tuple[int, ...]]:
    """Lyndon words over 0..dim-1 up to length `depth`, by length then lexicographically (Duval)."""
    words, w = [], [-1]
    while w:
        w[-1] += 1
        words.append(tuple(w))
        m = len(w)
        while len(w) < depth:
            w.append(w[len(w) - m])
        while w and w[-1] == dim - 1:
            w.pop()
    return sorted(words, key=lambda word: (len(word), word))


def word_index(word: tuple[int, ...], dim: int) -> int:
    """Position of a word in the flattened levels 1..depth (no scalar term)."""
    offset = sum(dim**k for k in range(1, len(word)))
    return offset + sum(letter * dim ** (len(word) - 1 - i) for i, letter in enumerate(word))


def flatten(levels: list[torch.Tensor]) -> torch.Tensor:
    """Levels 1..depth side by side, without the scalar term: [N, d + d^2 + ... + d^m]."""
    return torch.cat(levels[1:], 1)


def signature_features(path: torch.Tensor, depth: int, log_signature: bool) -> torch.Tensor:
    """Flat signature, or the log-signature's coefficients on the Lyndon words (signatory's "words")."""
    sig = signature(path, depth)
    if not log_signature:
        return flatten(sig)
    dim = path.shape[-1]
    index = torch.tensor([word_index(w, dim) for w in lyndon_words(dim, depth)], device=path.device)
    return flatten(log(sig))[:, index]


def signature_length(dim: int, depth: int) -> int:
    return sum(dim**k for k in range(1, depth + 1))


def log_signature_length(dim: int, depth: int) -> int:
    return len(lyndon_words(dim, depth))
