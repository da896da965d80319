//! rapier2d collision world: the ego and every actor as cuboid sensor colliders without
//! rigid bodies, moved by the tick pipeline and checked by rapier's collision pipeline
//! (BVH broad phase + narrow phase). Only ego–actor pairs are tested (collision groups).
//!
//! rapier2d works in f32; coordinates are taken relative to `origin` (the ego start) so that
//! large network coordinates keep millimetre precision.

use crate::geom::{Pose, Vec2};
use rapier2d::prelude::*;

const EGO_GROUP: Group = Group::GROUP_1;
const ACTOR_GROUP: Group = Group::GROUP_2;

pub(crate) struct CollisionWorld {
    origin: Vec2,
    bodies: RigidBodySet,
    colliders: ColliderSet,
    islands: IslandManager,
    broad: BroadPhaseBvh,
    narrow: NarrowPhase,
    pipeline: CollisionPipeline,
    ego: ColliderHandle,
}

impl std::fmt::Debug for CollisionWorld {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CollisionWorld")
            .field("origin", &self.origin)
            .field("colliders", &self.colliders.len())
            .finish()
    }
}

/// User-data tag of the ego collider.
const EGO_TAG: u128 = u128::MAX;

impl CollisionWorld {
    pub fn new(origin: Vec2, ego_pose: Pose, ego_length: f64, ego_width: f64) -> Self {
        let mut w = CollisionWorld {
            origin,
            bodies: RigidBodySet::new(),
            colliders: ColliderSet::new(),
            islands: IslandManager::new(),
            broad: BroadPhaseBvh::new(),
            narrow: NarrowPhase::new(),
            pipeline: CollisionPipeline::new(),
            ego: ColliderHandle::invalid(),
        };
        let groups = InteractionGroups::new(EGO_GROUP, ACTOR_GROUP, InteractionTestMode::And);
        w.ego = w.insert(EGO_TAG, ego_pose, ego_length, ego_width, groups);
        w
    }

    fn to_iso(&self, p: Pose) -> rapier2d::math::Pose {
        let d = p.pos - self.origin;
        rapier2d::math::Pose::new(rapier2d::math::Vector::new(d.x as Real, d.y as Real), p.yaw as Real)
    }

    fn insert(
        &mut self,
        tag: u128,
        pose: Pose,
        length: f64,
        width: f64,
        groups: InteractionGroups,
    ) -> ColliderHandle {
        let c = ColliderBuilder::cuboid((0.5 * length) as Real, (0.5 * width) as Real)
            .sensor(true)
            .active_collision_types(ActiveCollisionTypes::all())
            .collision_groups(groups)
            .user_data(tag)
            .position(self.to_iso(pose))
            .build();
        self.colliders.insert(c)
    }

    /// Adds an actor collider tagged with its id.
    pub fn add_actor(&mut self, id: u32, pose: Pose, length: f64, width: f64) -> ColliderHandle {
        let groups = InteractionGroups::new(ACTOR_GROUP, EGO_GROUP, InteractionTestMode::And);
        self.insert(id as u128, pose, length, width, groups)
    }

    pub fn set_pose(&mut self, h: ColliderHandle, pose: Pose) {
        let iso = self.to_iso(pose);
        if let Some(c) = self.colliders.get_mut(h) {
            c.set_position(iso);
        }
    }

    pub fn set_ego_pose(&mut self, pose: Pose) {
        self.set_pose(self.ego, pose);
    }

    pub fn set_enabled(&mut self, h: ColliderHandle, enabled: bool) {
        if let Some(c) = self.colliders.get_mut(h) {
            c.set_enabled(enabled);
        }
    }

    /// Runs broad + narrow phase and appends the ids of actors overlapping the ego to `out`
    /// (sorted, unique).
    pub fn ego_contacts(&mut self, out: &mut Vec<u32>) {
        self.pipeline.step(
            0.0,
            &mut self.islands,
            &mut self.broad,
            &mut self.narrow,
            &mut self.bodies,
            &mut self.colliders,
            &(),
            &(),
        );
        let start = out.len();
        for (a, b, hit) in self.narrow.intersection_pairs_with(self.ego) {
            if !hit {
                continue;
            }
            let other = if a == self.ego { b } else { a };
            if let Some(c) = self.colliders.get(other) {
                if c.is_enabled() && c.user_data != EGO_TAG {
                    out.push(c.user_data as u32);
                }
            }
        }
        out[start..].sort_unstable();
    }
}
