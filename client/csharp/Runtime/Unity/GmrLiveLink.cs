// A Unity component over the plain C# API (GmrClient.cs): it only calls that
// API. It subscribes to a view of a motion in Unity's conventions (Y up,
// Z forward, left-handed, metres) with local transforms, makes one Transform
// per joint under this GameObject (or uses the child Transforms already named
// after the joints: a rig whose bones carry the skeleton's names), and sets
// their localPosition and localRotation from the newest frame every Update.
// When the view's roots change while it streams, the hierarchy is rebuilt.
//
// Compiled only inside Unity (UNITY_5_3_OR_NEWER); the API beneath is tested
// under Mono (tests/csharp), this script is not run by the tests.
#if UNITY_5_3_OR_NEWER
using System.Collections.Generic;
using UnityEngine;

namespace Gmr.Unity
{
    public sealed class GmrLiveLink : MonoBehaviour
    {
        public string host = "127.0.0.1";
        public int port = 7400;
        [Tooltip("A token from the server's auth file; empty: anonymous")]
        public string token = "";
        public string motion = "walk";
        [Tooltip("Roots of the view, comma-separated; empty: the motion's own")]
        public string roots = "";
        [Tooltip("The motion seen from this joint; empty: world coordinates")]
        public string relativeTo = "";
        [Tooltip("The motion's unit in metres when the library does not know it (BVH); 0: the library's")]
        public double sourceMetresPerUnit = 0.0;
        public float speed = 1f;
        public bool loop = true;

        public string State { get; private set; }
        public ulong FrameIndex { get; private set; }
        public double LatencyMs { get; private set; }

        private Client client;
        private Subscription subscription;
        private Transform[] bones = new Transform[0];

        private void OnEnable()
        {
            try
            {
                client = Client.Connect(host, port, string.IsNullOrEmpty(token) ? null : token);
                uint view = client.CreateView(motion);
                if (!string.IsNullOrEmpty(roots)) client.SetRoots(view, roots.Split(','));
                if (!string.IsNullOrEmpty(relativeTo)) client.SetViewpoint(view, relativeTo);
                subscription = client.Subscribe(view, new SubscribeOptions
                {
                    Conventions = Conventions.Unity, LocalTransforms = true, Loop = loop, Speed = speed,
                    SourceMetresPerUnit = sourceMetresPerUnit,
                });
                Build();
                State = "streaming";
                if (subscription.MetresPerUnit == 0)
                    Debug.LogWarning("gmr live link: the unit of " + motion + " is unknown, so its numbers are the file's, " +
                                     "not metres: set sourceMetresPerUnit, or declare the unit beside the file (X.units)");
            }
            catch (GmrException e)
            {
                State = e.Message;
                Debug.LogWarning("gmr live link: " + e.Message);
                OnDisable();
            }
        }

        private void OnDisable()
        {
            if (client != null) client.Dispose();
            client = null;
            subscription = null;
        }

        // One Transform per joint, parented as the skeleton says, at its rest pose.
        private void Build()
        {
            var existing = new Dictionary<string, Transform>();
            foreach (Transform t in GetComponentsInChildren<Transform>()) existing[t.name] = t;
            JointInfo[] joints = subscription.Joints;
            bones = new Transform[joints.Length];
            for (int i = 0; i < joints.Length; i++)
            {
                Transform t;
                if (!existing.TryGetValue(joints[i].Name, out t)) t = new GameObject(joints[i].Name).transform;
                t.SetParent(joints[i].Parent < 0 ? transform : bones[joints[i].Parent], false);
                bones[i] = t;
            }
        }

        private void Update()
        {
            if (subscription == null || !subscription.Poll())
            {
                if (subscription != null && subscription.Ended) State = "ended: " + subscription.EndReason;
                return;
            }
            if (subscription.SkeletonChanged) Build();
            double[] r = subscription.LocalRotations, p = subscription.LocalTranslations;
            for (int i = 0; i < bones.Length; i++)
            {
                bones[i].localRotation = new Quaternion((float)r[4 * i], (float)r[4 * i + 1], (float)r[4 * i + 2], (float)r[4 * i + 3]);
                bones[i].localPosition = new Vector3((float)p[3 * i], (float)p[3 * i + 1], (float)p[3 * i + 2]);
            }
            FrameIndex = subscription.FrameIndex;
            LatencyMs = subscription.LatencyMs();
        }
    }
}
#endif
