"""MP4 video of a run: MuJoCo renders offscreen, ffmpeg encodes."""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import mujoco

from .camera import aim_at_robot
from .runner import Hook, Simulation

FPS = 25  # 40 control steps per frame at 1 kHz
WIDTH, HEIGHT = 640, 480


class VideoUnavailable(RuntimeError):
    """No OpenGL backend for offscreen rendering, or no MP4 encoder."""


def find_encoder() -> str:
    """Path of an ffmpeg executable: on PATH, or the one the imageio-ffmpeg package ships."""
    found = shutil.which("ffmpeg")
    if found:
        return found
    try:
        import imageio_ffmpeg
    except ImportError:
        raise VideoUnavailable(
            "no MP4 encoder: --video needs ffmpeg (apt-get install ffmpeg, or pip install imageio-ffmpeg)"
        ) from None
    return imageio_ffmpeg.get_ffmpeg_exe()


class VideoRecorder:
    """Renders the simulation about FPS times per simulated second and pipes the frames to ffmpeg.

    The file is written next to `path` and renamed when complete, so a failed run leaves none.
    """

    def __init__(self, sim: Simulation, path: Path):
        self.path = Path(path)
        self._partial = self.path.with_name(f".{self.path.name}.partial.mp4")
        encoder = find_encoder()
        self._model, self._data = sim.mj_model, sim.mj_data
        try:
            self._renderer = mujoco.Renderer(self._model, HEIGHT, WIDTH)
        except Exception as error:  # MuJoCo raises FatalError, ImportError or RuntimeError here
            backend = os.environ.get("MUJOCO_GL", "glfw")
            raise VideoUnavailable(
                f"no OpenGL backend for offscreen rendering (MUJOCO_GL={backend}: {error}); "
                "install EGL or OSMesa (apt-get install libegl1 or libosmesa6) and set MUJOCO_GL=egl or osmesa"
            ) from None
        self._camera = mujoco.MjvCamera()
        sim.reset()
        aim_at_robot(self._camera, self._model, self._data)
        self.every = max(1, round(1.0 / (FPS * sim.scenario.period)))
        fps = 1.0 / (self.every * sim.scenario.period)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        command = [encoder, "-y", "-loglevel", "error", "-f", "rawvideo", "-pix_fmt", "rgb24",
                   "-s", f"{WIDTH}x{HEIGHT}", "-r", f"{fps:g}", "-i", "-", "-an",
                   "-vcodec", "libx264", "-pix_fmt", "yuv420p", "-f", "mp4", str(self._partial)]
        self._encoder = subprocess.Popen(command, stdin=subprocess.PIPE, stderr=subprocess.PIPE)
        self.frames = 0
        self.render()

    def hook(self) -> Hook:
        return Hook(self.every, lambda k: self.render())

    def render(self) -> None:
        # After mj_step the positions are those of the previous state.
        mujoco.mj_fwdPosition(self._model, self._data)
        self._renderer.update_scene(self._data, self._camera)
        assert self._encoder.stdin is not None
        self._encoder.stdin.write(self._renderer.render().tobytes())
        self.frames += 1

    def close(self, keep: bool = True) -> None:
        """Finish the file (or drop it when `keep` is False)."""
        assert self._encoder.stdin is not None and self._encoder.stderr is not None
        self._encoder.stdin.close()
        errors = self._encoder.stderr.read()  # little: ffmpeg runs with -loglevel error
        self._encoder.wait()
        self._renderer.close()
        if keep and self._encoder.returncode == 0:
            self._partial.replace(self.path)
            return
        self._partial.unlink(missing_ok=True)
        if keep:
            raise VideoUnavailable(f"ffmpeg could not encode the video: {errors.decode(errors='replace').strip()}")
