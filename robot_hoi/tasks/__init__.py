"""Tasks: an environment config + its MDP terms (observations, rewards, terminations) per folder."""
