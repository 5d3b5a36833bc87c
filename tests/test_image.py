"""utils.image: exact 8-bit round trips, alpha handling, PSNR closed form."""
from __future__ import annotations

import numpy as np
import pytest
import torch
from PIL import Image

from utils.image import load_rgba, save_image


@pytest.mark.parametrize("channels", [3, 4])
def test_round_trip_is_exact_on_8bit_values(tmp_path, channels):
    levels = torch.randint(0, 256, (channels, 5, 7)).float()
    save_image(levels / 255, tmp_path / "sub" / "a.png")  # creates the folder
    back = load_rgba(tmp_path / "sub" / "a.png")
    assert back.shape == (4, 5, 7) and back.dtype == torch.float32
    torch.testing.assert_close(back[:channels] * 255, levels, atol=1e-4, rtol=0)  # float32 of k/255 * 255
    if channels == 3:
        assert torch.all(back[3] == 1)


def test_save_rounds_and_clamps(tmp_path):
    img = torch.tensor([-0.5, 1.7, 0.5 / 255 + 1e-4, 0.5 / 255 - 1e-4]).reshape(1, 1, 4).repeat(3, 1, 1)
    save_image(img, tmp_path / "a.png")
    assert np.asarray(Image.open(tmp_path / "a.png"))[0, :, 0].tolist() == [0, 255, 1, 0]
    with pytest.raises(AssertionError, match=r"\[3\|4, H, W\]"):
        save_image(torch.zeros(2, 4, 4), tmp_path / "b.png")
