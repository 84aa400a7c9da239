"""One router per resource: health, models, sessions, inference steps, the stream."""
