"""The deployable student: a Transformer distilled from the teachers (InterMimic Sec. 3.3-3.4, Alg. 1), with the
ComplexMimic and SkillMimic-V2 options. Entry point: `robot-hoi train student` (robot_hoi.student.launch.run,
which runs pipeline.train)."""
