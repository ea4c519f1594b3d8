"""The temporal stage: motion models and history resolved on the device."""
