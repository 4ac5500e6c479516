"""The run wing: Simulation (the step loop, summaries), output files (frames, summaries, histories,
pictures, plots). The top of the runtime."""
