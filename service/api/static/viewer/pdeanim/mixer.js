// Drive a player from three.js's AnimationMixer: an AnimationClip whose action time maps linearly onto the
// clip's normalised time t, so that crossFadeTo, fadeIn/fadeOut, weights, timeScale, loop modes and the
// mixer's 'loop' / 'finished' events work as for any other clip, mixed with other animations of the model.
//
// The clip has one two-component track (influence w, w * t) bound to the player through the root it plays
// on: the mixer blends it like any property, and the player shows t = (w t) / w at influence w.
//
// On a skinned model the clip's vertices replace the skinned ones by the influence, and the skinned side is
// drawn with the bones the mixer blends. A clip action without bone tracks leaves the rest of the bones'
// weight to three.js, which fills it with the bind pose: a crossfade from a skinned walk would pass through
// it. With `pose` (the skeletal animation the clip was fitted on) the action also drives the bones at that
// pose, at the clip's time, so the mixer blends the bones as between any two skeletal actions.

import { AnimationClip, VectorKeyframeTrack } from 'three';

let nextKey = 0;

/** Seconds of a decoded clip: its source frames' span (cyclic clips: one period), 1 when unknown. */
export function clipDuration(clip) {
  if (clip.kind === 'cyclic-spine') return clip.period;
  const times = clip.frameTimes;
  const span = times && times.length > 1 ? times[times.length - 1] - times[0] : 0;
  return span > 0 ? span : 1;
}

/** The object the mixer's binding writes into: fromArray takes the blended (w, w t). */
function mixTarget(player) {
  return {
    fromArray(array, offset = 0) {
      const w = array[offset];
      if (!(w > 1e-6)) {
        player.influence = 0;
        return;
      }
      let t = array[offset + 1] / w;
      if (!player.clip.looping) t = Math.min(Math.max(t, 0), 1); // blending may overshoot by rounding
      player.influence = Math.min(w, 1);
      player.setTime(t);
    },
    toArray(array, offset = 0) {
      array[offset] = player.influence;
      array[offset + 1] = player.influence * player.time;
      return array;
    },
  };
}

/**
 * An AnimationClip that plays player (a ClipPlayer or ScenePlayer) through an AnimationMixer whose root is
 * the player's mesh or root, or an ancestor of it: action time 0 .. duration maps to t = 0 .. 1. options:
 * name (default 'pdeanim'), duration in seconds (default: the clip's, clipDuration), pose (an AnimationClip:
 * the skeletal animation the clip was fitted on, its time 0 .. duration mapped onto t = 0 .. 1; the action then
 * also drives those bones, so that crossfades with skeletal actions blend bones between poses rather than
 * with the bind pose). Creating it hands the player's influence to the mixer: it starts at 0 (the model as
 * without the clip) and follows the action's effective weight.
 */
export function clipAnimation(player, { name = 'pdeanim', duration = clipDuration(player.clip), pose = null } = {}) {
  if (!(duration > 0)) throw new RangeError(`duration must be > 0 seconds, got ${duration}`);
  if (pose !== null && !(pose instanceof AnimationClip || Array.isArray(pose?.tracks))) {
    throw new TypeError('pose must be a three.js AnimationClip (the skeletal animation the clip was fitted on)');
  }
  if (pose && !(pose.duration > 0)) throw new RangeError(`the pose clip ${pose.name} has no duration`);
  const root = player.root ?? player.mesh;
  if (!Object.hasOwn(root, 'pdeanim')) {
    Object.defineProperty(root, 'pdeanim', { value: {}, configurable: true, enumerable: false });
  }
  player._mixKey ??= `p${nextKey++}`;
  root.pdeanim[player._mixKey] = { state: mixTarget(player) };
  player.influence = 0;
  const track = new VectorKeyframeTrack(`${root.uuid}.pdeanim[${player._mixKey}].state`, [0, duration], [1, 0, 1, 1]);
  // the pose's time 0 .. its duration is the clip's t = 0 .. 1 (the frames the clip was fitted on)
  const poseTracks = (pose?.tracks ?? []).map((k) => k.clone().scale(duration / pose.duration));
  return new AnimationClip(name, duration, [track, ...poseTracks]);
}
