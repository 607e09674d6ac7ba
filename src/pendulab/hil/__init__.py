"""Hardware in the loop: the rig protocol, the serial link, the rig-clocked loop and the rig emulator."""
