"""swarmloc.leaderboard."""
