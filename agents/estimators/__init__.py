"""Track B estimators: dead reckoning, particle filters, IMM, federated and CI-EKF filters."""
