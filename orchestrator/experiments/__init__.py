"""The paper's Sec. V on the closed loop: scenarios, experiments, diagnosis, baseline
gains, the report and the walker's animation."""
