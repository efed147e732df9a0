"""What pyproject.toml cannot say: configs/, urdf/ and policies/ stay at the repository root and ship inside the
wheel as robot_hoi/configs, robot_hoi/urdf and robot_hoi/policies (robot_hoi.paths finds either place), and the
embodiment YAMLs as deploy/embodiments (deploy.embodiment finds either place)."""

from setuptools import find_packages, setup

# package -> (folder at the repository root, files shipped); policies: the tracked files only (.gitignore)
DATA = {
    "robot_hoi.configs": ("configs", ["**/*.yaml"]),
    "robot_hoi.urdf": ("urdf", ["*.urdf"]),
    "robot_hoi.policies": ("policies", ["*.md", "*.pt", "lift_place_student.onnx", "lift_place_student.motion.npz"]),
    "deploy.embodiments": ("configs/embodiments", ["*.yaml"]),
}

setup(
    packages=find_packages(include=["robot_hoi*", "deploy*", "sim2sim*"]) + list(DATA),
    package_dir={package: folder for package, (folder, _) in DATA.items()},
    package_data={package: files for package, (_, files) in DATA.items()},
)
