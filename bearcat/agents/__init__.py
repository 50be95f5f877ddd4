"""Sans-IO agents: plain classes with handle(message, now) and tick(now) that return messages to send."""
