"""One package per paper's flight software (one room each). Every package here is imported by
agent.controller.load_controllers(), so its controllers register themselves by decorator."""
