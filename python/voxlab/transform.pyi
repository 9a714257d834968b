from typing import Any, Callable, Iterator, Literal, Optional, Sequence, Tuple

import numpy as np
from numpy.typing import ArrayLike

def iradon(radon_image: ArrayLike, theta: Optional[ArrayLike] = None,
           output_size: Optional[int] = None,
           filter_name: Optional[Literal["ramp", "shepp-logan", "cosine", "hamming", "hann"]] = "ramp",
           interpolation: Literal["linear", "nearest", "cubic"] = "linear",
           circle: bool = True, preserve_range: bool = True, *,
           backend: Literal["cpu", "cpu-f32", "gpu", "auto"] = "cpu",
           progress: Optional[Callable[[str, int, int], Any]] = None) -> np.ndarray: ...
def radon(image: ArrayLike, theta: Optional[ArrayLike] = None, circle: bool = True, *,
          preserve_range: bool = False,
          backend: Literal["cpu", "cpu-f32", "gpu", "auto"] = "cpu",
          progress: Optional[Callable[[str, int, int], Any]] = None) -> np.ndarray: ...
def order_angles_golden_ratio(theta: ArrayLike) -> Iterator[int]: ...
def iradon_sart(radon_image: ArrayLike, theta: Optional[ArrayLike] = None,
                image: Optional[ArrayLike] = None,
                projection_shifts: Optional[ArrayLike] = None,
                clip: Optional[Sequence[float]] = None, relaxation: float = 0.15,
                dtype: Any = None, *,
                backend: Literal["cpu", "cpu-f32", "gpu", "auto"] = "cpu",
                progress: Optional[Callable[[str, int, int], Any]] = None) -> np.ndarray: ...
