"""The build step pyproject.toml cannot declare: the bundled configs, kept once at the top of the
repository (``configs/``), copied into the package of a wheel (``quadctl/configs/``), where
``quadctl configs`` and ``--config NAME`` find them when quadctl is installed. Everything else is in
pyproject.toml."""

from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

CONFIGS = Path(__file__).resolve().parent / "configs"


class BuildWithConfigs(build_py):
    """``build_py``, then ``configs/*.yaml`` into ``<build>/quadctl/configs/``."""

    def run(self):
        super().run()
        target = Path(self.build_lib) / "quadctl" / "configs"
        self.mkpath(str(target))
        for path in sorted(CONFIGS.glob("*.yaml")):
            self.copy_file(str(path), str(target / path.name))

    def get_outputs(self, include_bytecode=True):
        target = Path(self.build_lib) / "quadctl" / "configs"
        return [*super().get_outputs(include_bytecode), *(str(target / p.name) for p in sorted(CONFIGS.glob("*.yaml")))]


setup(cmdclass={"build_py": BuildWithConfigs})
