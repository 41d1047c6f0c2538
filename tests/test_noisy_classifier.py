"""The guidance networks of Alg. 1 and 2: the noisy classifier and the text head."""
import torch

from facelib.models.noisy_classifier import NoisyTextHead, TextHeadConfig


def test_noisy_classifier_reads_motion_and_ignores_padding(small_classifier):
    clf, _ = small_classifier
    x, t = torch.randn(2, 12, 68, 3), torch.tensor([5.0, 50.0])
    shifted = x + torch.randn(2, 1, 68, 3)  # another anatomy: the same motion
    assert torch.allclose(clf(x, t), clf(shifted, t), atol=1e-5)
    mask = torch.ones(2, 12, dtype=torch.bool)
    mask[:, 9:] = False
    padded = x.clone()
    padded[:, 9:] = 100.0
    assert torch.allclose(clf(x[:, :9], t), clf(padded, t, mask), atol=1e-5)
    assert clf(x, t).shape == (2, 3)


def test_text_head_outputs_unit_vectors_of_motion():
    torch.manual_seed(0)
    h = NoisyTextHead(TextHeadConfig(embedding_dim=16, width=32, depth=1, heads=2, ff=32, dropout=0.0)).eval()
    x, t = torch.randn(3, 10, 68, 3), torch.tensor([0.0, 10.0, 500.0])
    e = h.embed(x, t)
    assert e.shape == (3, 16)
    torch.testing.assert_close(e.norm(dim=1), torch.ones(3))
    torch.testing.assert_close(h.embed(x + torch.randn(3, 1, 68, 3), t), e, atol=1e-5, rtol=1e-5)  # motion only
    c = torch.randn(16)
    cos = h.cosine(x, t, c)
    assert cos.shape == (3,) and (cos.abs() <= 1 + 1e-6).all()
    torch.testing.assert_close(cos, torch.nn.functional.cosine_similarity(h(x, t), c[None], dim=1))
