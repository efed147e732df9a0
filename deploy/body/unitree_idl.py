"""Unitree G1 low-level DDS message types ("hg" family) as cyclonedds IdlStruct dataclasses.

Type names and field order match the robot's IDL (unitree_hg.msg.dds_.*), so these are wire-compatible without
the Unitree SDK. Importing this module needs cyclonedds (optional extra `deploy-dds`); deploy.body.unitree_dds
imports it only when a DDS body is actually used. No `from __future__ import annotations` here: cyclonedds
resolves the field annotations at run time.
"""

from dataclasses import dataclass

import cyclonedds.idl.types as t
from cyclonedds.idl import IdlStruct

NUM_MOTOR_SLOTS = 35  # same as deploy.body.unitree_lowlevel.NUM_MOTOR_SLOTS


@dataclass
class MotorCmd_(IdlStruct, typename="unitree_hg.msg.dds_.MotorCmd_"):
    mode: t.uint8
    q: t.float32
    dq: t.float32
    tau: t.float32
    kp: t.float32
    kd: t.float32
    reserve: t.uint32


@dataclass
class LowCmd_(IdlStruct, typename="unitree_hg.msg.dds_.LowCmd_"):
    mode_pr: t.uint8
    mode_machine: t.uint8
    motor_cmd: t.array[MotorCmd_, 35]
    reserve: t.array[t.uint32, 4]
    crc: t.uint32


@dataclass
class IMUState_(IdlStruct, typename="unitree_hg.msg.dds_.IMUState_"):
    quaternion: t.array[t.float32, 4]  # w, x, y, z
    gyroscope: t.array[t.float32, 3]
    accelerometer: t.array[t.float32, 3]
    rpy: t.array[t.float32, 3]
    temperature: t.int16


@dataclass
class MotorState_(IdlStruct, typename="unitree_hg.msg.dds_.MotorState_"):
    mode: t.uint8
    q: t.float32
    dq: t.float32
    ddq: t.float32
    tau_est: t.float32
    temperature: t.array[t.int16, 2]
    vol: t.float32
    sensor: t.array[t.uint32, 2]
    motorstate: t.uint32
    reserve: t.array[t.uint32, 4]


@dataclass
class LowState_(IdlStruct, typename="unitree_hg.msg.dds_.LowState_"):
    version: t.array[t.uint32, 2]
    mode_pr: t.uint8
    mode_machine: t.uint8
    tick: t.uint32
    imu_state: IMUState_
    motor_state: t.array[MotorState_, 35]
    wireless_remote: t.array[t.uint8, 40]
    reserve: t.array[t.uint32, 4]
    crc: t.uint32
