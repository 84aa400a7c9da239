"""The varied-task benchmark: four skills whose cube, goal, speed and obstacle change every episode, nine fault families, rivals and an oracle."""
