"""Control: joint trajectories and the joint-space tracking controller used by the demo."""
