"""What a task is: its spec, the catalogue of registered tasks, its channel layout, seeds and random streams, the task pages."""
