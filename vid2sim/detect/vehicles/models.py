"""Registry of known detector weights: where to find them locally and how to download them."""

from __future__ import annotations

import contextlib
import hashlib
import os
import tempfile
import urllib.request
from dataclasses import dataclass
from pathlib import Path

from vid2sim.base.errors import FormatError, InputError, MissingInputError

MODEL_DIR_ENV = "VID2SIM_MODEL_DIR"
DEFAULT_DETECTOR = "yolox-nano"
"""The detector used when none is named: with its half-frame tiles it is the one that reaches
the KITTI recall/precision bar (see benchmarks/bench_detect.py)."""


@dataclass(frozen=True, slots=True)
class ModelSpec:
    """One known detector.

    :param name: registry name used on the command line (``--detector NAME``)
    :param filename: file name of the weights in a model folder
    :param url: upstream release the weights are downloaded from
    :param sha256: checksum of the weights this project was validated with
    :param input_size_px: (width, height) of the fixed network input [px]
    :param decoder: output decoder, "yolox" or "picodet"
    :param also_accepted_sha256: other checksums of the same weights (e.g. an upstream asset
        re-uploaded with different ONNX metadata)
    """

    name: str
    filename: str
    url: str
    sha256: str
    input_size_px: tuple[int, int]
    decoder: str
    description: str = ""
    also_accepted_sha256: tuple[str, ...] = ()

    def accepts(self, digest: str) -> bool:
        """True if ``digest`` (hex sha256) is a checksum of these weights."""
        return digest.lower() in (self.sha256, *self.also_accepted_sha256)


MODELS: dict[str, ModelSpec] = {
    spec.name: spec
    for spec in (
        ModelSpec(
            name="yolox-nano",
            filename="yolox_nano.onnx",
            url="https://github.com/Megvii-BaseDetection/YOLOX/releases/download/0.1.1rc0/"
                "yolox_nano.onnx",
            sha256="e8af074932d4ed7e232278e3055cefcdea3edf178874a3694ae292649fb464dd",
            # Public projects pinning the 0.1.1rc0 release asset report this checksum
            # (3,659,407 bytes); the copy this project was validated with differs in size.
            # Unverified here (no network): accepted so `models pull` can work upstream.
            also_accepted_sha256=(
                "c789161ed43c8269fcd4e67c67eeeb4e80c622da2eb296a20bc6007bd18a0b7d",),
            input_size_px=(416, 416),
            decoder="yolox",
            description="YOLOX-nano (Megvii), COCO mAP 25.8, Apache-2.0",
        ),
        ModelSpec(
            name="picodet-s",
            filename="picodet_s_416_coco.onnx",
            url="https://paddledet.bj.bcebos.com/deploy/third_engine/picodet_s_416_coco.onnx",
            sha256="cdab77bdde16e4f76bec734c4e5791801d1739e4c7ec1995e0e110e04300d0c2",
            input_size_px=(416, 416),
            decoder="picodet",
            description="PP-PicoDet-S 416 (PaddleDetection 2021.10), COCO mAP 30.7, Apache-2.0",
        ),
    )
}


def cache_dir() -> Path:
    """User cache of downloaded weights (``$XDG_CACHE_HOME/vid2sim/models``, else ~/.cache)."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "vid2sim" / "models"


def get_spec(name: str) -> ModelSpec:
    """The registry entry for ``name``; InputError listing the known names otherwise."""
    try:
        return MODELS[name]
    except KeyError:
        raise FormatError(None, f"unknown detector '{name}'",
                          f"known: {', '.join(MODELS)}; or give a path to an .onnx file") from None


def search_dirs(model_dir: Path | None = None) -> list[Path]:
    """Folders searched for weights, in order: ``model_dir``, $VID2SIM_MODEL_DIR, user cache."""
    dirs = []
    if model_dir is not None:
        dirs.append(Path(model_dir))
    if os.environ.get(MODEL_DIR_ENV):
        dirs.append(Path(os.environ[MODEL_DIR_ENV]))
    dirs.append(cache_dir())
    return dirs


def spec_for_path(path: Path) -> ModelSpec | None:
    """The registry entry whose file name matches ``path``, if any (to pick the decoder)."""
    for spec in MODELS.values():
        if Path(path).name == spec.filename:
            return spec
    return None


def resolve_model(name_or_path: str | Path, model_dir: Path | None = None) -> Path:
    """Find the weights file for a registry name or an explicit path.

    Parameters
    ----------
    name_or_path : str or Path
        A registry name ("yolox-nano", "picodet-s") or a path to an .onnx file.
    model_dir : Path, optional
        Folder to search first (the ``--model-dir`` option).

    Returns
    -------
    Path
        An existing weights file.

    Raises
    ------
    InputError
        If the path does not exist, or the named weights are in none of the search folders.
    """
    text = str(name_or_path)
    if text not in MODELS:
        path = Path(text)
        if path.suffix.lower() == ".onnx" or os.sep in text or path.exists():
            if not path.is_file():
                raise MissingInputError(path, "detector weights file not found")
            return path
        get_spec(text)  # raises with the list of known names
    spec = MODELS[text]
    dirs = search_dirs(model_dir)
    for folder in dirs:
        candidate = folder / spec.filename
        if candidate.is_file():
            return candidate
    raise MissingInputError(
        None, f"weights for '{spec.name}' ({spec.filename}) not found in "
        + ", ".join(str(d) for d in dirs),
        f"run `vid2sim models pull {spec.name}` on a machine with internet, or set "
        f"{MODEL_DIR_ENV} / --model-dir to a folder holding {spec.filename}")


def pull(name: str, dest_dir: Path | None = None, *, url: str | None = None,
         progress: bool = True, timeout_s: float = 60.0) -> Path:
    """Download registry weights, verify their sha256 and move them into place.

    The download goes to a temporary file beside the destination and is renamed only after
    the checksum matches, so an interrupted or corrupted download never looks like weights.

    Parameters
    ----------
    name : str
        Registry name.
    dest_dir : Path, optional
        Target folder (default: the user cache, see :func:`cache_dir`).
    url : str, optional
        Override the upstream URL (a mirror; tests use a local ``file://`` URL).
    progress : bool
        Show a tqdm progress bar on stderr.
    timeout_s : float
        Network timeout per read [s].

    Returns
    -------
    Path
        The verified weights file.

    Raises
    ------
    InputError
        On a network failure or a checksum mismatch.
    """
    from tqdm import tqdm

    spec = get_spec(name)
    dest_dir = Path(dest_dir) if dest_dir is not None else cache_dir()
    dest = dest_dir / spec.filename
    source = url or spec.url
    dest_dir.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{spec.filename}.", suffix=".part", dir=dest_dir)
    tmp = Path(tmp_name)
    digest = hashlib.sha256()
    try:
        try:
            with os.fdopen(fd, "wb") as out, \
                    urllib.request.urlopen(source, timeout=timeout_s) as response:
                total = int(response.headers.get("Content-Length") or 0) or None
                with tqdm(total=total, unit="B", unit_scale=True, desc=spec.filename,
                          disable=not progress) as bar:
                    while chunk := response.read(1 << 16):
                        out.write(chunk)
                        digest.update(chunk)
                        bar.update(len(chunk))
        except OSError as exc:  # URLError and socket errors are OSErrors
            raise InputError(source, f"download failed: {exc}",
                             f"check the network, or fetch the file by hand into {dest_dir}"
                             ) from exc
        got = digest.hexdigest()
        if not spec.accepts(got):
            raise InputError(source, f"checksum mismatch: got sha256 {got}, expected "
                             f"{spec.sha256}", "the download is corrupt or the upstream file "
                             "changed; nothing was installed")
        os.replace(tmp, dest)
    finally:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
    return dest


def describe_models(model_dir: Path | None = None) -> str:
    """One line per registry model: name, input size, where its weights are (or 'not found')."""
    lines = []
    for spec in MODELS.values():
        try:
            where = str(resolve_model(spec.name, model_dir))
        except InputError:
            where = f"not found (vid2sim models pull {spec.name})"
        w, h = spec.input_size_px
        lines.append(f"{spec.name:12s} {w}x{h}  {spec.description}\n{'':12s} {where}")
    return "\n".join(lines)
